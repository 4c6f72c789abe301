// A bounded multi-producer multi-consumer queue joining the daemon's threads.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

namespace sl::daemon {

// Thread-safe. Overflow policy: push() never blocks; when the queue is full the
// oldest element is dropped and counted (a real-time sensor prefers the newest
// scan to a growing backlog). close() wakes every waiting consumer; pops then
// drain what is left and return nullopt once empty.
template <typename T>
class BoundedQueue {
 public:
  explicit BoundedQueue(std::size_t capacity) : capacity_(capacity ? capacity : 1) {}

  // Returns false if an element had to be dropped to make room (or the queue
  // is closed, in which case `value` is dropped).
  bool push(T value) {
    bool dropped = false;
    {
      std::lock_guard lock(mutex_);
      if (closed_) {
        ++dropped_;
        return false;
      }
      if (items_.size() >= capacity_) {
        items_.pop_front();
        ++dropped_;
        dropped = true;
      }
      items_.push_back(std::move(value));
    }
    ready_.notify_one();
    return !dropped;
  }

  // Waits up to `timeout` for an element.
  std::optional<T> pop(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    ready_.wait_for(lock, timeout, [&] { return closed_ || !items_.empty(); });
    if (items_.empty()) return std::nullopt;
    T value = std::move(items_.front());
    items_.pop_front();
    return value;
  }

  void close() {
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
  }

  // Removes every queued element (counted as dropped); returns how many.
  std::size_t clear() {
    std::lock_guard lock(mutex_);
    const std::size_t n = items_.size();
    items_.clear();
    dropped_ += n;
    return n;
  }

  std::uint64_t dropped() const {
    std::lock_guard lock(mutex_);
    return dropped_;
  }
  std::size_t size() const {
    std::lock_guard lock(mutex_);
    return items_.size();
  }

 private:
  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<T> items_;        // guarded by mutex_
  std::uint64_t dropped_ = 0;  // guarded by mutex_
  bool closed_ = false;        // guarded by mutex_
};

}  // namespace sl::daemon
