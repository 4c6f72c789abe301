// What a reloaded config (SIGHUP) changes that a running daemon cannot take.
#include <set>

#include <yaml-cpp/yaml.h>

#include "sl/daemon/config.h"

namespace sl::daemon {

std::vector<std::string> keysNeedingRestart(const DaemonConfig& running, const DaemonConfig& loaded) {
  const YAML::Node a = YAML::Load(running.source_text), b = YAML::Load(loaded.source_text);
  static const std::set<std::string> kReloadable = {"decoder", "triangulator", "motion_compensation"};
  auto dump = [](const YAML::Node& n) { return n ? YAML::Dump(n) : std::string(); };
  std::set<std::string> keys;
  for (const auto* root : {&a, &b})
    for (const auto& entry : *root) keys.insert(entry.first.as<std::string>());
  std::vector<std::string> changed;
  for (const std::string& key : keys) {
    if (kReloadable.count(key)) continue;
    if (key == "dds") {  // everything but the status period needs a restart
      std::set<std::string> sub;
      for (const auto* root : {&a, &b})
        if ((*root)["dds"] && (*root)["dds"].IsMap())
          for (const auto& entry : (*root)["dds"]) sub.insert(entry.first.as<std::string>());
      for (const std::string& s : sub)
        if (s != "status_period_s" && dump(a["dds"][s]) != dump(b["dds"][s])) changed.push_back("dds." + s);
      continue;
    }
    if (dump(a[key]) != dump(b[key])) changed.push_back(key);
  }
  return changed;
}

}  // namespace sl::daemon
