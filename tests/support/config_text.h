// Test support: the shipped config/sim.yaml as text, and the error message
// the config parser gives for a YAML text.
#pragma once

#include <fstream>
#include <sstream>
#include <string>

#include "sl/daemon/config.h"

namespace sl::test {

inline std::string shippedSimConfigText() {
  std::ifstream in(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The ConfigError message for `yaml` (parsed as "test.yaml"); empty if it loads.
inline std::string configErrorOf(const std::string& yaml) {
  try {
    daemon::parseConfig(yaml, "test.yaml");
  } catch (const files::ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace sl::test
