// The sd_notify(3) protocol without libsystemd: a datagram to the AF_UNIX
// socket named by $NOTIFY_SOCKET ("@" prefix = abstract namespace).
#pragma once

#include <chrono>
#include <optional>
#include <string>

namespace sl::daemon {

// Sends `state` (e.g. "READY=1", "STOPPING=1", "WATCHDOG=1", "STATUS=...").
// Returns false when not run by systemd (no $NOTIFY_SOCKET) or on failure.
bool systemdNotify(const std::string& state);

// The watchdog interval requested by systemd ($WATCHDOG_USEC), if any.
std::optional<std::chrono::microseconds> systemdWatchdogInterval();

}  // namespace sl::daemon
