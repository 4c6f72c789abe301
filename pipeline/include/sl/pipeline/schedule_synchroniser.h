// Grouping across the projector's schedules: the Synchroniser (eq. 12) for
// each pattern the projector runs, and the boundaries between them, so that
// no image set ever mixes two patterns across a switch.
//
// A run (one request) starts with startRun(). A pattern switch within the run
// happens at a sequence boundary: holdFrom(boundary) when the switch is
// decided (the sequence in progress completes, whatever is stamped at or after
// the boundary belongs to no set), then switchPattern() when the projector
// starts the new pattern. The old pattern's schedule keeps what is stamped
// before the boundary until its last sequence completes or ages out.
#pragma once

#include <cstdint>
#include <deque>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "sl/pipeline/synchroniser.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct ScheduleCounters {
  std::uint64_t sets_completed = 0;
  std::uint64_t frames_unmatched = 0;     // purged or dropped without belonging to any set
  std::uint64_t triggers_incomplete = 0;  // sequences purged or abandoned before every frame arrived
  // Frames and triggers stamped outside every schedule: between a switch's
  // boundary and the new pattern's start, before a run's start, or while no
  // run is active. Expected around switches; not faults.
  std::uint64_t stamps_outside = 0;
};

// Thread-compatible: one thread pushes, controls and collects.
//
// Sequence ids increase from 0 within a run, across its pattern switches.
// Every schedule of a run is a Synchroniser over a stamp interval
// [not_before, boundary - tol_l * dt): the sequence starting at the boundary
// is not the schedule's, and its first frame may be stamped up to tol_l * dt
// early. A stamp is grouped by the schedule whose interval holds it. A schedule that is no longer running is retired (what it still
// holds counted as incomplete / unmatched) once a stamp newer than its
// boundary + max_age arrives, or when its run ends with endRun(true).
class ScheduleSynchroniser {
 public:
  static constexpr TimestampNs kNoHold = std::numeric_limits<TimestampNs>::max();

  // Throws std::invalid_argument as Synchroniser does.
  ScheduleSynchroniser(std::vector<std::string> camera_ids, SynchroniserOptions options);

  // A new run of `pattern`: what earlier runs still hold is dropped (counted);
  // stamps before not_before_ns belong to no set.
  void startRun(std::string pattern, int frame_count, TimestampNs not_before_ns);
  // The projector stopped the running pattern at sequence boundary
  // `boundary_ns` and starts `pattern` at or after not_before_ns (>= boundary).
  void switchPattern(std::string pattern, int frame_count, TimestampNs not_before_ns,
                     TimestampNs boundary_ns);
  // A switch is pending at `at_ns`: stamps at or after it (less tol_l * dt)
  // belong to no set until switchPattern(). kNoHold releases the hold (switch cancelled).
  void holdFrom(TimestampNs at_ns);
  // The run ended. What is still held is a sequence the stop cut short
  // (count_pending false: dropped silently) or one whose frames were lost
  // (count_pending true: counted as incomplete / unmatched).
  void endRun(bool count_pending);

  // Throws std::out_of_range on a camera index outside camera_ids.
  void pushFrame(std::size_t camera_index, Frame frame);
  void pushTrigger(TimestampNs trigger_stamp_ns);

  // Image sets completed since the last call, in completion order.
  std::vector<std::shared_ptr<const ImageSet>> takeCompleted();

  // Totals since construction.
  ScheduleCounters counters() const;
  // The latest trigger grouped for the running pattern (0: none yet).
  TimestampNs lastTriggerNs() const { return last_trigger_ns_; }
  bool running() const { return running_; }

 private:
  struct Schedule {
    Synchroniser synchroniser;
    TimestampNs from_ns = 0;
    TimestampNs until_ns = kNoHold;  // the switch boundary; kNoHold while running
  };
  Schedule* route(TimestampNs stamp);
  void retire(Schedule& schedule, bool count_pending);
  void retireAll(bool count_pending);
  void retireExpired(TimestampNs stamp);
  void collect(Schedule& schedule);

  std::vector<std::string> camera_ids_;
  SynchroniserOptions options_;
  std::deque<Schedule> schedules_;  // oldest first; back() runs while running_
  bool running_ = false;
  TimestampNs hold_from_ns_ = kNoHold;
  TimestampNs last_trigger_ns_ = 0;
  std::uint64_t next_sequence_id_ = 0;
  std::uint64_t stamps_outside_ = 0;
  SynchroniserCounters retired_;  // of schedules no longer held
  std::vector<std::shared_ptr<const ImageSet>> completed_;
};

}  // namespace sl::pipeline
