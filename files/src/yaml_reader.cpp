#include "sl/files/yaml_reader.h"

#include <array>
#include <cstdint>

namespace sl::files {

namespace {

std::string where(const std::string& origin, const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  if (mark.line < 0) return origin;
  return origin + ":" + std::to_string(mark.line + 1);
}

template <typename T>
const char* typeName() {
  if constexpr (std::is_same_v<T, bool>) return "a boolean (true/false)";
  else if constexpr (std::is_integral_v<T>) return "an integer";
  else if constexpr (std::is_floating_point_v<T>) return "a number";
  else if constexpr (std::is_same_v<T, std::string>) return "a string";
  else return "a list of numbers";
}

// yaml-cpp keeps both entries of a key given twice and finds the first, so
// the second would be silently ignored: refused, in every map of the file.
void rejectDuplicateKeys(const YAML::Node& node, const std::string& origin, const std::string& path,
                         int depth) {
  if (depth > 64) throw ConfigError(where(origin, node) + ": nested more than 64 levels deep");
  if (node.IsMap()) {
    std::set<std::string> seen;
    for (const auto& entry : node) {
      const std::string key = entry.first.IsScalar() ? entry.first.Scalar() : "<complex key>";
      const std::string key_path = path.empty() ? key : path + "." + key;
      if (!seen.insert(key).second)
        throw ConfigError(where(origin, entry.first) + ": key '" + key_path +
                          "' appears twice in the same map");
      rejectDuplicateKeys(entry.second, origin, key_path, depth + 1);
    }
  } else if (node.IsSequence()) {
    std::size_t i = 0;
    for (const auto& item : node)
      rejectDuplicateKeys(item, origin, path + "[" + std::to_string(i++) + "]", depth + 1);
  }
}

}  // namespace

YamlMap::YamlMap(const YAML::Node& node, std::string origin, std::string path)
    : node_(node), origin_(std::move(origin)), path_(std::move(path)) {
  if (node_ && !node_.IsNull() && !node_.IsMap())
    throw ConfigError(where(origin_, node_) + ": key '" + (path_.empty() ? "<root>" : path_) +
                      "': expected a map of keys");
  // A file's root map checks the whole document once.
  if (path_.empty() && node_) rejectDuplicateKeys(node_, origin_, "", 0);
}

std::string YamlMap::keyPath(const std::string& key) const {
  return path_.empty() ? key : path_ + "." + key;
}

void YamlMap::fail(const std::string& key, const std::string& message) const {
  const YAML::Node value = node_ && node_.IsMap() ? node_[key] : YAML::Node();
  throw ConfigError(where(origin_, value ? value : node_) + ": key '" + keyPath(key) + "': " +
                    message);
}

bool YamlMap::has(const std::string& key) const {
  return node_ && node_.IsMap() && node_[key];
}

std::optional<YAML::Node> YamlMap::lookup(const std::string& key) const {
  used_.insert(key);
  if (!has(key)) return std::nullopt;
  return node_[key];
}

template <typename T>
T YamlMap::convert(const std::string& key, const YAML::Node& value) const {
  if constexpr (std::is_same_v<T, std::vector<double>>) {
    if (!value.IsSequence()) fail(key, std::string("expected ") + typeName<T>());
    std::vector<double> out;
    for (const auto& item : value) {
      try {
        out.push_back(item.as<double>());
      } catch (const YAML::Exception&) {
        fail(key, "expected a list of numbers, found '" + YAML::Dump(item) + "'");
      }
    }
    return out;
  } else {
    if (!value.IsScalar())
      fail(key, std::string("expected ") + typeName<T>() + ", found a " +
                    (value.IsSequence() ? "list" : "map"));
    try {
      return value.as<T>();
    } catch (const YAML::Exception&) {
      fail(key, std::string("expected ") + typeName<T>() + ", found '" + value.Scalar() + "'");
    }
  }
}

template <typename T>
T YamlMap::get(const std::string& key) const {
  const auto value = lookup(key);
  if (!value) {
    throw ConfigError(where(origin_, node_) + ": key '" + keyPath(key) + "' is required");
  }
  return convert<T>(key, *value);
}

template <typename T>
T YamlMap::get(const std::string& key, const T& fallback) const {
  const auto value = lookup(key);
  if (!value) return fallback;
  return convert<T>(key, *value);
}

YamlMap YamlMap::map(const std::string& key) const {
  const auto value = lookup(key);
  if (!value) throw ConfigError(where(origin_, node_) + ": key '" + keyPath(key) + "' is required");
  return YamlMap(*value, origin_, keyPath(key));
}

YamlMap YamlMap::optionalMap(const std::string& key) const {
  return YamlMap(lookup(key).value_or(YAML::Node()), origin_, keyPath(key));
}

std::vector<YamlMap> YamlMap::listOfMaps(const std::string& key) const {
  const auto value = lookup(key);
  if (!value) throw ConfigError(where(origin_, node_) + ": key '" + keyPath(key) + "' is required");
  if (!value->IsSequence() || value->size() == 0) fail(key, "expected a non-empty list");
  std::vector<YamlMap> out;
  for (std::size_t i = 0; i < value->size(); ++i)
    out.emplace_back((*value)[i], origin_, keyPath(key) + "[" + std::to_string(i) + "]");
  return out;
}

YAML::Node YamlMap::raw(const std::string& key) const {
  return lookup(key).value_or(YAML::Node());
}

void YamlMap::done() const {
  if (!node_ || !node_.IsMap()) return;
  for (const auto& entry : node_) {
    if (!entry.first.IsScalar())
      throw ConfigError(where(origin_, entry.first) + ": key '" + keyPath("<list or map>") +
                        "': keys must be plain names");
    const std::string key = entry.first.Scalar();
    if (!used_.count(key))
      throw ConfigError(where(origin_, entry.first) + ": unknown key '" + keyPath(key) + "'");
  }
}

template bool YamlMap::get<bool>(const std::string&) const;
template int YamlMap::get<int>(const std::string&) const;
template double YamlMap::get<double>(const std::string&) const;
template std::string YamlMap::get<std::string>(const std::string&) const;
template std::vector<double> YamlMap::get<std::vector<double>>(const std::string&) const;
template bool YamlMap::get<bool>(const std::string&, const bool&) const;
template int YamlMap::get<int>(const std::string&, const int&) const;
template double YamlMap::get<double>(const std::string&, const double&) const;
template std::uint64_t YamlMap::get<std::uint64_t>(const std::string&, const std::uint64_t&) const;
template std::string YamlMap::get<std::string>(const std::string&, const std::string&) const;
template std::vector<double> YamlMap::get<std::vector<double>>(
    const std::string&, const std::vector<double>&) const;

Eigen::Vector3d vec3(const YamlMap& m, const std::string& key) {
  const auto v = m.get<std::vector<double>>(key);
  if (v.size() != 3) m.fail(key, "expected 3 numbers, found " + std::to_string(v.size()));
  return {v[0], v[1], v[2]};
}

Eigen::Vector3d vec3(const YamlMap& m, const std::string& key, const Eigen::Vector3d& fallback) {
  return m.has(key) ? vec3(m, key) : fallback;
}

double positive(const YamlMap& m, const std::string& key, double fallback) {
  const double v = m.get<double>(key, fallback);
  if (!(v > 0)) m.fail(key, "must be > 0");
  return v;
}

double nonNegative(const YamlMap& m, const std::string& key, double fallback) {
  const double v = m.get<double>(key, fallback);
  if (!(v >= 0)) m.fail(key, "must be >= 0");
  return v;
}

}  // namespace sl::files
