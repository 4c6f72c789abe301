// YAML of the `projector:` and `trigger:` sections for `sensor: hardware`.
#pragma once

#include "sl/daemon/config.h"
#include "sl/files/yaml_reader.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::YamlMap;

// Parses `projector:` and `trigger:` into config.hardware and checks that
// every pattern of config.patterns has a projector sequence of the same name
// and frame count. Throws ConfigError naming file, line and key.
void parseHardware(const YamlMap& root, DaemonConfig& config);
// Images per second for the synchroniser: 1 / the projector frame period of
// the patterns' sequences (all must share one period).
double hardwareImageRate(const YamlMap& root, const DaemonConfig& config);

}  // namespace sl::daemon
