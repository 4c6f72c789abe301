// The engine's counts and rates for the status topic: what each thread
// counted (frames received, unmatched, sequences incomplete) and the rates
// derived from them.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

#include "engine/stage_latency.h"
#include "recorder.h"
#include "sl/daemon/scan_engine.h"  // EngineStatus

namespace sl::daemon {

// Thread-safe: counters are atomics written by the thread that owns the
// count; the rates take their own mutex.
class EngineStatistics {
 public:
  using Clock = std::chrono::steady_clock;

  // Camera frames received (all cameras); camera and control threads.
  void framesReceived(std::uint64_t n) { frames_received_ += n; }
  // Totals of the two groupings (trigger time: grouping thread; software
  // trigger: control thread), stored after each push.
  struct GroupingCounts {
    std::uint64_t frames_unmatched = 0;
    std::uint64_t sets_incomplete = 0;
  };
  void setTriggerGrouping(GroupingCounts counts);
  void setSoftwareGrouping(GroupingCounts counts);
  std::uint64_t framesUnmatched() const;
  std::uint64_t setsIncomplete() const;

  // A scan of request `generation` was published (output thread).
  void scanPublished(std::uint64_t generation);
  // Scans per second over the last (up to) 10 scans of `generation`: stable,
  // and quick to follow a switch; 0 before two scans of it. When no scan came
  // for longer than 1.5 mean intervals, the time since the last one counts
  // too (the rate falls), and after `stall_s` without a scan it is 0.
  double scanRateHz(std::uint64_t generation, double stall_s) const;
  // When the last scan of `generation` was published (nullopt: none yet) and
  // how many sequences were incomplete since then.
  std::optional<Clock::time_point> lastScan(std::uint64_t generation) const;
  std::uint64_t incompleteSinceLastScan() const { return setsIncomplete() - incomplete_at_scan_.load(); }
  // Frames per second over windows of at least a second (status() is polled
  // often; the window moves on when asked after a second).
  double frameRateHz();

  // Where each published scan's latency went (output thread) and its
  // summary over the last scans (any thread).
  void scanStages(const StageTimes& scan) { stages_.add(scan); }
  StageSummary stageSummary() const { return stages_.summary(); }

  // Its part of `status` (any thread): the counts and rates kept here
  // (frame rate, incomplete sets, latencies); frames_unmatched is the
  // engine's (it adds the software trigger's stale frames).
  void fillStatus(EngineStatus& status);

 private:
  std::atomic<std::uint64_t> frames_received_{0};
  std::atomic<std::uint64_t> unmatched_trigger_{0}, unmatched_software_{0};
  std::atomic<std::uint64_t> incomplete_trigger_{0}, incomplete_software_{0};
  std::atomic<std::uint64_t> incomplete_at_scan_{0};  // setsIncomplete() at the last scan
  StageLatency stages_;

  mutable std::mutex mutex_;
  std::uint64_t scan_generation_ = 0;      // guarded by mutex_
  std::deque<Clock::time_point> recent_;   // guarded by mutex_
  Clock::time_point window_start_ = Clock::now();  // guarded by mutex_
  std::uint64_t window_frames_ = 0;        // guarded by mutex_
  double frame_rate_hz_ = 0;               // guarded by mutex_
};

// The recorder's part of `status`: its counts (sets_not_recorded also in
// sets_dropped), the recording cleared once it stopped by itself, and its
// latest error as last_error when newer than the status's own and not older
// than `last_error_hold_s` (0 = no limit) at `now_ns` (system clock).
void addRecorderStatus(EngineStatus& status, const Recorder& recorder, double last_error_hold_s,
                       pipeline::TimestampNs now_ns);

}  // namespace sl::daemon
