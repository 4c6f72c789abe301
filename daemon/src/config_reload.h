// What a SIGHUP reload may change, listed once (config_reload.cpp).
#pragma once

#include <string>
#include <vector>

namespace sl::daemon {

// The keys a running daemon takes on a reload, top-level or dotted
// ("dds.status_period_s"); keysNeedingRestart() leaves exactly these out.
const std::vector<std::string>& reloadableKeys();

// reloadableKeys() as "a, b, c" (log lines).
std::string reloadableKeysText();

}  // namespace sl::daemon
