// Writes image sets to a recording (sl/drivers/recording.h) on its own
// thread, so that PNG encoding never stalls the pipeline.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "sl/daemon/bounded_queue.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

// Thread-safe. Overflow policy: a full queue drops the oldest set (counted in
// dropped()); a write error stops the recording and is kept in lastError().
class Recorder {
 public:
  explicit Recorder(std::size_t queue_depth = 8);
  ~Recorder();  // finishes the queued sets, then joins

  // Starts writing into `dir` (created if needed; sets continue the
  // numbering of a recording already there). Throws std::runtime_error
  // naming the folder if it cannot be created.
  void start(const std::string& dir, const std::string& note);
  // Stops accepting sets; queued sets are still written.
  void stop();
  bool active() const { return active_; }

  // Queues a set if recording; never blocks.
  void record(std::shared_ptr<const pipeline::ImageSet> set);

  std::uint64_t written() const { return written_; }
  std::uint64_t dropped() const { return queue_.dropped(); }
  std::string lastError() const;

 private:
  void run();

  struct Item {
    std::string dir;
    std::uint64_t index = 0;  // set number within dir, assigned when queued
    std::shared_ptr<const pipeline::ImageSet> set;
  };
  BoundedQueue<Item> queue_;
  std::atomic<bool> active_{false};
  std::atomic<bool> running_{true};
  std::atomic<std::uint64_t> written_{0};
  mutable std::mutex mutex_;
  std::string dir_;            // guarded by mutex_
  std::uint64_t next_index_ = 1;  // guarded by mutex_
  std::string last_error_;     // guarded by mutex_
  std::thread thread_;
};

}  // namespace sl::daemon
