// Groups camera frames into pattern sequences by projector trigger time
// (paper eq. 12): frame i (0-based) of a sequence triggered at t_p is the one
// whose stamp t_c satisfies
//   -tol_lower <= t_c - (t_p + i * dt_img) <= tol_upper.
#pragma once

#include <cstdint>
#include <deque>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct SynchroniserOptions {
  TimestampNs image_interval_ns = 33'333'333;  // dt_img: time between camera triggers
  double tolerance_lower = 0.2;                // tol_l as a fraction of dt_img
  double tolerance_upper = 0.2;                // tol_u as a fraction of dt_img
  // Frames and triggers older than this behind the newest stamp are purged.
  TimestampNs max_age_ns = 2'000'000'000;
};

struct SynchroniserCounters {
  std::uint64_t sets_completed = 0;
  std::uint64_t frames_unmatched = 0;    // purged without belonging to any sequence
  std::uint64_t triggers_incomplete = 0; // purged before every frame arrived
};

// Thread-compatible: one thread pushes frames and triggers and collects sets.
//
// Triggers and frames may arrive in any order; each push tries to complete
// the pending sequences, oldest trigger first. A sequence completes when every
// camera has a frame in each of the frame_count windows; the set then holds
// the frames in pattern order, cameras in camera_ids order, bit_depth of the
// camera's first frame, and sequence ids increasing from 0 across patterns.
// Purging uses the newest stamp seen (frames and triggers): a trigger older
// than newest - max_age is counted in triggers_incomplete; a frame is counted
// in frames_unmatched once t_c + tol_l * dt < newest - max_age (every trigger
// it could belong to is purged by then). Before the first setPattern nothing
// matches and everything ages out. The constructor throws
// std::invalid_argument on no cameras, dt <= 0, max_age <= 0, or tolerances
// that are negative or sum to >= 1 (windows would overlap).
class Synchroniser {
 public:
  // camera_ids: one entry per camera; frame_count: patterns per sequence.
  Synchroniser(std::vector<std::string> camera_ids, SynchroniserOptions options);

  // Starts a new pattern: pending frames and triggers are dropped (counted).
  void setPattern(std::string pattern_name, int frame_count);

  void pushTrigger(TimestampNs trigger_stamp_ns);
  // Throws std::out_of_range on a camera index outside camera_ids.
  void pushFrame(std::size_t camera_index, Frame frame);

  // Image sets completed since the last call, oldest first.
  std::vector<std::shared_ptr<const ImageSet>> takeCompleted();

  const SynchroniserCounters& counters() const { return counters_; }

 private:
  void match();
  void purge(TimestampNs newest);

  std::vector<std::string> camera_ids_;
  SynchroniserOptions options_;
  std::string pattern_name_;
  int frame_count_ = 0;
  std::uint64_t next_sequence_id_ = 0;
  TimestampNs newest_stamp_ns_ = std::numeric_limits<TimestampNs>::min();
  std::deque<TimestampNs> triggers_;
  std::vector<std::deque<Frame>> frames_;  // per camera, in arrival order
  std::vector<std::shared_ptr<const ImageSet>> completed_;
  SynchroniserCounters counters_;
};

}  // namespace sl::pipeline
