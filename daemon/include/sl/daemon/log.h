// Minimal line logging to stderr (the journal under systemd). Thread-safe:
// each call writes one whole line: control characters in the message
// (newlines, escape sequences from a client's id) are escaped by logSafe, so
// no text can forge or split lines.
#pragma once

#include <cstddef>
#include <string>

namespace sl::daemon {

// `text` with control characters (< 0x20, 0x7f) as \xNN and backslashes
// doubled, cut after max_bytes with the original length noted.
std::string logSafe(const std::string& text, std::size_t max_bytes = 4096);

void logInfo(const std::string& message);
void logWarning(const std::string& message);
void logError(const std::string& message);

}  // namespace sl::daemon
