// Minimal line logging to stderr (the journal under systemd). Thread-safe:
// each call writes one whole line.
#pragma once

#include <string>

namespace sl::daemon {

void logInfo(const std::string& message);
void logWarning(const std::string& message);
void logError(const std::string& message);

}  // namespace sl::daemon
