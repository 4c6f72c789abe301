#include "sl/daemon/log.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <mutex>

namespace sl::daemon {

namespace {

std::mutex log_mutex;

// Under systemd (JOURNAL_STREAM set) lines carry the sd-daemon(3) "<N>"
// level prefix the journal understands; on a terminal they do not.
void write(const char* level, const std::string& message) {
  static const bool journal = std::getenv("JOURNAL_STREAM") != nullptr;
  const std::string line = logSafe(message);
  std::lock_guard lock(log_mutex);
  std::fprintf(stderr, "%ssl_sensord: %s\n", journal ? level : "", line.c_str());
  std::fflush(stderr);
}

}  // namespace

std::string logSafe(const std::string& text, std::size_t max_bytes) {
  std::string out;
  const std::size_t n = std::min(text.size(), max_bytes);
  out.reserve(n + 32);
  static const char* kHex = "0123456789abcdef";
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\\') {
      out += "\\\\";
    } else if (c < 0x20 || c == 0x7f) {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    } else {
      out += static_cast<char>(c);  // printable ASCII and UTF-8 bytes
    }
  }
  if (text.size() > n) out += "...(" + std::to_string(text.size()) + " bytes)";
  return out;
}

void logInfo(const std::string& message) { write("<6>", message); }
void logWarning(const std::string& message) { write("<4>", message); }
void logError(const std::string& message) { write("<3>", message); }

}  // namespace sl::daemon
