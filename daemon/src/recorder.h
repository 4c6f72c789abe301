// Writes image sets to a recording (sl/drivers/recording.h) on its own
// thread, so that PNG encoding never stalls the pipeline.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "sl/daemon/bounded_queue.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

// Limits of a recording (runtime.recording_*); 0 = no limit.
struct RecordingQuota {
  std::uint64_t max_bytes = 0;       // per recording (what this recording wrote)
  std::uint64_t max_sets = 0;        // per recording
  std::uint64_t min_free_bytes = 0;  // free space kept on the recording's file system
};

// Thread-safe. Overflow policy: a full queue drops the oldest set (counted in
// dropped()); a write error (e.g. a full disk) stops the recording and is
// kept in lastError(): the set that failed, the sets of that recording still
// queued and every later set of it offered to record() are counted in
// notWritten() (dropped() + notWritten() = notRecorded()).
// Before each set is written its raw image size is checked against the
// quota; a set that would exceed it stops the recording (lastError() says
// which limit), and it and every later set of that recording are counted in
// overQuota().
class Recorder {
 public:
  explicit Recorder(std::size_t queue_depth = 8, RecordingQuota quota = {});
  ~Recorder();  // finishes the queued sets, then joins

  // Starts writing into `dir` (created if needed; sets continue the
  // numbering of a recording already there). Throws std::runtime_error
  // naming the folder if it cannot be created, or when its file system has
  // less than the free-space floor left. Each set of a pattern of
  // `patterns` gets its description (pattern.yml, files::patternYaml()).
  void start(const std::string& dir, const std::string& note,
             const std::vector<pipeline::PatternSpec>& patterns = {});
  // Stops accepting sets; queued sets are still written.
  void stop();
  bool active() const { return active_; }

  // Queues a set if recording; never blocks.
  void record(std::shared_ptr<const pipeline::ImageSet> set);

  std::uint64_t written() const { return written_; }
  std::uint64_t dropped() const { return queue_.dropped(); }
  std::uint64_t overQuota() const { return over_quota_; }
  std::uint64_t notWritten() const { return not_written_; }
  // Sets not recorded but for the quota: queue overflow and write errors.
  std::uint64_t notRecorded() const { return dropped() + notWritten(); }
  struct Error {
    std::string message;              // "" = none
    std::int64_t stamp_ns = 0;        // system clock
    std::uint64_t count = 0;          // errors since start-up
  };
  Error lastError() const;

 private:
  void run();
  // "" when `set` fits; else why not (names the limit).
  std::string quotaProblem(const std::string& dir, const pipeline::ImageSet& set) const;

  struct Item {
    std::string dir;
    std::uint64_t index = 0;  // set number within dir, assigned when queued
    std::uint64_t epoch = 0;  // of the recording (each start and stop begins a new one)
    std::shared_ptr<const pipeline::ImageSet> set;
    std::string pattern_yaml;  // "" = no description of the set's pattern
  };
  const RecordingQuota quota_;
  BoundedQueue<Item> queue_;
  std::atomic<bool> active_{false};
  std::atomic<bool> running_{true};
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> over_quota_{0};
  mutable std::mutex mutex_;
  std::string dir_;               // guarded by mutex_
  std::map<std::string, std::string> pattern_yaml_;  // by pattern name; guarded by mutex_
  std::uint64_t next_index_ = 1;  // guarded by mutex_
  // The current recording hit its quota: its further sets are counted, not
  // queued (until stop() or start()).
  std::atomic<bool> quota_reached_{false};
  // The current recording failed to write a set: its further sets are
  // counted in not_written_, not queued (until stop() or start()).
  std::atomic<bool> write_failed_{false};
  std::atomic<std::uint64_t> not_written_{0};
  std::uint64_t failed_epoch_ = 0;     // guarded by mutex_: the recording that failed
  std::uint64_t epoch_ = 0;            // guarded by mutex_
  std::uint64_t quota_epoch_ = 0;      // guarded by mutex_: the recording that hit its quota
  std::uint64_t recording_bytes_ = 0;  // guarded by mutex_: written to dir_ since start()
  std::uint64_t recording_sets_ = 0;   // guarded by mutex_
  Error error_;                   // guarded by mutex_
  std::thread thread_;
};

}  // namespace sl::daemon
