// YAML of the simulated sensor; called from config.cpp (parseRoot).
#pragma once

#include <filesystem>

#include "sl/drivers/sim.h"
#include "sl/files/yaml_reader.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::YamlMap;

// Reads `sim:` into `sim` (files such as meshes and textures relative to
// base_dir). Throws ConfigError naming file, line and key.
void parseSim(const YamlMap& m, const std::filesystem::path& base_dir, drivers::SimConfig& sim);

}  // namespace sl::daemon
