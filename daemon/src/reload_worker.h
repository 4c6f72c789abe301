// Loading a config for a reload (SIGHUP) off the signal path (private to
// daemon/): the load runs on a thread of its own, so the main thread keeps
// taking signals (SIGTERM ends the daemon) whatever the load does, and it
// has a deadline: a load that has not returned by then is refused (and
// abandoned: it may be blocked in a read for ever; its result is dropped).
// Not thread-safe: one owner (the main loop) calls begin() and poll().
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "sl/daemon/config.h"

namespace sl::daemon {

class ReloadWorker {
 public:
  using Loader = std::function<DaemonConfig(const std::string& path)>;
  using Clock = std::chrono::steady_clock;

  ReloadWorker(Loader loader, std::chrono::milliseconds deadline);
  // Never waits for a load: a running one is left to finish on its own.
  ~ReloadWorker();
  ReloadWorker(const ReloadWorker&) = delete;
  ReloadWorker& operator=(const ReloadWorker&) = delete;

  // Starts loading `path`. Returns "" when started, else why not (nothing
  // started): the load begun before has not returned, also one abandoned
  // past its deadline -- a second thread would block on the same file.
  std::string begin(const std::string& path, Clock::time_point now = Clock::now());

  struct Outcome {
    enum class Kind { kLoaded, kFailed, kTimedOut };
    Kind kind = Kind::kFailed;
    std::string path;
    std::optional<DaemonConfig> config;  // kLoaded
    std::string error;                   // kFailed: the loader's message
  };
  // The outcome of the load begun last, given once: when the load returned,
  // or kTimedOut once its deadline passed. nullopt while it runs within its
  // deadline, or when no outcome is due.
  std::optional<Outcome> poll(Clock::time_point now = Clock::now());

  bool pending() const { return pending_; }  // an outcome is due (poll() soon)
  std::chrono::milliseconds deadline() const { return deadline_; }

  // Load threads of every ReloadWorker that have not returned (abandoned
  // ones included): at exit, a process with one skips the static
  // destructors (std::_Exit) rather than run them under a thread that may
  // still be inside a library.
  static int threadsRunning();

 private:
  struct State;
  Loader loader_;
  std::chrono::milliseconds deadline_;
  std::shared_ptr<State> state_;  // of the load begun last
  std::string path_;
  Clock::time_point begun_{}, due_{};
  bool pending_ = false;
};

}  // namespace sl::daemon
