// YAML of the Aravis cameras; called from config.cpp (parseRoot).
#pragma once

#include "sl/daemon/config.h"
#include "yaml_reader.h"

namespace sl::daemon {

// Reads `cameras:` (sensor hardware and fake_gige) and `fake_gige:` (sensor
// fake_gige) into config.aravis. For fake_gige, config.sim must be parsed
// already: the camera must match the simulated camera. Throws ConfigError
// naming file, line and key.
void parseAravisSection(const YamlMap& root, DaemonConfig& config);

}  // namespace sl::daemon
