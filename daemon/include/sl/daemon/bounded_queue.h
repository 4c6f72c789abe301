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

// What push() does when the queue is full.
enum class Overflow {
  // Drop the oldest element and count it: a real-time sensor prefers the
  // newest frame or scan to a growing backlog.
  kDropOldest,
  // Wait until a consumer made room (or the queue closed): for channels where
  // every element matters and the consumer never blocks for long.
  kWaitForRoom,
};

// Thread-safe. close() wakes every waiting producer and consumer: pushes then
// drop their element (counted) and return false; pops drain what is left and
// return nullopt once empty.
template <typename T>
class BoundedQueue {
 public:
  explicit BoundedQueue(std::size_t capacity, Overflow overflow = Overflow::kDropOldest)
      : capacity_(capacity ? capacity : 1), overflow_(overflow) {}

  // Returns false if an element was dropped: the oldest, to make room
  // (kDropOldest), or `value` itself because the queue is closed.
  bool push(T value) {
    bool dropped = false;
    {
      std::unique_lock lock(mutex_);
      if (overflow_ == Overflow::kWaitForRoom)
        room_.wait(lock, [&] { return closed_ || items_.size() < capacity_; });
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
    return takeFront(lock);
  }
  // The front element if there is one; never waits.
  std::optional<T> tryPop() {
    std::unique_lock lock(mutex_);
    return takeFront(lock);
  }

  void close() {
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
    room_.notify_all();
  }

  // Removes every queued element (counted as dropped); returns how many.
  std::size_t clear() {
    std::size_t n = 0;
    {
      std::lock_guard lock(mutex_);
      n = items_.size();
      items_.clear();
      dropped_ += n;
    }
    room_.notify_all();
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
  std::size_t capacity() const { return capacity_; }

 private:
  std::optional<T> takeFront(std::unique_lock<std::mutex>& lock) {
    if (items_.empty()) return std::nullopt;
    T value = std::move(items_.front());
    items_.pop_front();
    lock.unlock();
    room_.notify_one();
    return value;
  }

  const std::size_t capacity_;
  const Overflow overflow_;
  mutable std::mutex mutex_;
  std::condition_variable ready_;  // an element arrived or the queue closed
  std::condition_variable room_;   // an element left or the queue closed
  std::deque<T> items_;        // guarded by mutex_
  std::uint64_t dropped_ = 0;  // guarded by mutex_
  bool closed_ = false;        // guarded by mutex_
};

}  // namespace sl::daemon
