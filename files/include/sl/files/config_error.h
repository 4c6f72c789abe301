// The error every reader of user files throws (configs, pattern files,
// calibrations).
#pragma once

#include <stdexcept>

namespace sl::files {

// A configuration error: the message names the file, the key and, where
// known, the line ("config/sim.yaml:12: key 'sim.camera.fx': expected a number").
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace sl::files
