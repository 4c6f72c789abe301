// Thread plumbing of the scan engine: heartbeats for the watchdog, and the
// gate that parks the camera threads while the control thread grabs itself
// (software trigger).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>

namespace sl::daemon {

// Thread-safe: one thread beats, any thread asks.
class Heartbeat {
 public:
  using Clock = std::chrono::steady_clock;
  void beat() { last_ = Clock::now().time_since_epoch().count(); }
  bool recent(std::chrono::nanoseconds max_age) const {
    return Clock::now().time_since_epoch().count() - last_.load() < max_age.count();
  }

 private:
  std::atomic<Clock::rep> last_{Clock::now().time_since_epoch().count()};
};

// Thread-safe. The camera threads call parkIfHeld() before each grab; the
// control thread hold()s them all, grabs, and release()s them.
class CameraGate {
 public:
  explicit CameraGate(std::size_t cameras) : cameras_(cameras) {}

  // Camera thread: while held, waits here (beating `alive` every 100 ms)
  // until released or `open()` turns false. True if it parked.
  bool parkIfHeld(const std::function<void()>& alive, const std::function<bool()>& open) {
    using namespace std::chrono_literals;
    std::unique_lock lock(mutex_);
    if (!held_) return false;
    ++parked_;
    cv_.notify_all();
    while (held_ && open()) {
      cv_.wait_for(lock, 100ms);
      alive();
    }
    --parked_;
    return true;
  }
  // Control thread: holds every camera thread (each finishes the grab in
  // progress); false when they did not all park within `timeout`.
  bool hold(std::chrono::milliseconds timeout, const std::function<void()>& alive) {
    using namespace std::chrono_literals;
    std::unique_lock lock(mutex_);
    held_ = true;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (parked_ < cameras_ && std::chrono::steady_clock::now() < deadline) {
      cv_.wait_for(lock, 100ms);
      alive();
    }
    return parked_ == cameras_;
  }
  void release() {
    {
      std::lock_guard lock(mutex_);
      held_ = false;
    }
    cv_.notify_all();
  }
  // Runs `change` (e.g. clearing the engine's running flag) under the gate's
  // mutex and wakes every parked thread, so that none misses it.
  void wakeAll(const std::function<void()>& change) {
    {
      std::lock_guard lock(mutex_);
      change();
    }
    cv_.notify_all();
  }

 private:
  const std::size_t cameras_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool held_ = false;       // guarded by mutex_
  std::size_t parked_ = 0;  // guarded by mutex_
};

}  // namespace sl::daemon
