// YAML of the Aravis cameras; called from config.cpp (parseRoot).
#pragma once

#include "sl/daemon/config.h"
#include "sl/files/yaml_reader.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::YamlMap;

// Reads `cameras:` (sensor hardware and fake_gige) and `fake_gige:` (sensor
// fake_gige) into config.aravis. For fake_gige, config.sim must be parsed
// already: the camera must match the simulated camera. Throws ConfigError
// naming file, line and key.
void parseAravisSection(const YamlMap& root, DaemonConfig& config);

}  // namespace sl::daemon
