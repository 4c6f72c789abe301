#include "sl/daemon/log.h"

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
  std::lock_guard lock(log_mutex);
  std::fprintf(stderr, "%ssl_sensord: %s\n", journal ? level : "", message.c_str());
  std::fflush(stderr);
}

}  // namespace

void logInfo(const std::string& message) { write("<6>", message); }
void logWarning(const std::string& message) { write("<4>", message); }
void logError(const std::string& message) { write("<3>", message); }

}  // namespace sl::daemon
