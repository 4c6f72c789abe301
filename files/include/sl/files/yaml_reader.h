// Strict reading of YAML maps: every read names its key path, every error
// names the file, line and key, and done() rejects keys nobody read.
#pragma once

#include <optional>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include "sl/files/config_error.h"

namespace sl::files {

// Thread-compatible; lives only while one file is parsed.
class YamlMap {
 public:
  // node must be a map (or null, read as an empty map).
  YamlMap(const YAML::Node& node, std::string origin, std::string path);

  bool has(const std::string& key) const;

  template <typename T>
  T get(const std::string& key) const;  // required
  template <typename T>
  T get(const std::string& key, const T& fallback) const;  // optional

  YamlMap map(const std::string& key) const;           // required map
  YamlMap optionalMap(const std::string& key) const;   // empty map if absent
  std::vector<YamlMap> listOfMaps(const std::string& key) const;  // required, non-empty
  YAML::Node raw(const std::string& key) const;  // marks the key used; Null if absent

  // Throws ConfigError naming the first key that was never read.
  void done() const;

  [[noreturn]] void fail(const std::string& key, const std::string& message) const;
  const std::string& origin() const { return origin_; }
  std::string keyPath(const std::string& key) const;

 private:
  std::optional<YAML::Node> lookup(const std::string& key) const;  // marks used
  template <typename T>
  T convert(const std::string& key, const YAML::Node& value) const;

  YAML::Node node_;
  std::string origin_;
  std::string path_;
  mutable std::set<std::string> used_;
};

// Typed helpers shared by the config and calibration readers.
Eigen::Vector3d vec3(const YamlMap& m, const std::string& key);  // required, 3 numbers
Eigen::Vector3d vec3(const YamlMap& m, const std::string& key, const Eigen::Vector3d& fallback);
double positive(const YamlMap& m, const std::string& key, double fallback);     // > 0
double nonNegative(const YamlMap& m, const std::string& key, double fallback);  // >= 0

}  // namespace sl::files
