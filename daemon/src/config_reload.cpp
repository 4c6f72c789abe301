// What a reloaded config (SIGHUP) changes that a running daemon cannot take.
#include <set>

#include <yaml-cpp/yaml.h>

#include "config_reload.h"
#include "sl/daemon/config.h"

namespace sl::daemon {

const std::vector<std::string>& reloadableKeys() {
  static const std::vector<std::string> keys = {"decoder", "triangulator", "motion_compensation",
                                                "dds.status_period_s"};
  return keys;
}

std::string reloadableKeysText() {
  std::string text;
  for (const auto& k : reloadableKeys()) text += (text.empty() ? "" : ", ") + k;
  return text;
}

std::vector<std::string> keysNeedingRestart(const DaemonConfig& running, const DaemonConfig& loaded) {
  const YAML::Node a = YAML::Load(running.source_text), b = YAML::Load(loaded.source_text);
  const std::set<std::string> reloadable(reloadableKeys().begin(), reloadableKeys().end());
  auto dump = [](const YAML::Node& n) { return n ? YAML::Dump(n) : std::string(); };
  std::set<std::string> keys;
  for (const auto* root : {&a, &b})
    for (const auto& entry : *root) keys.insert(entry.first.as<std::string>());
  std::vector<std::string> changed;
  for (const std::string& key : keys) {
    if (reloadable.count(key)) continue;
    if (key == "dds") {  // each dds key on its own
      std::set<std::string> sub;
      for (const auto* root : {&a, &b})
        if ((*root)["dds"] && (*root)["dds"].IsMap())
          for (const auto& entry : (*root)["dds"]) sub.insert(entry.first.as<std::string>());
      for (const std::string& s : sub)
        if (!reloadable.count("dds." + s) && dump(a["dds"][s]) != dump(b["dds"][s]))
          changed.push_back("dds." + s);
      continue;
    }
    if (dump(a[key]) != dump(b[key])) changed.push_back(key);
  }
  return changed;
}

}  // namespace sl::daemon
