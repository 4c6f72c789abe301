// Grouping of frames whose pattern index is known because whoever triggered
// the cameras showed that pattern itself (software trigger: show pattern i,
// trigger, grab): the sibling of the trigger-time Synchroniser for setups
// without a trigger board. It builds the same ImageSets and counts the same
// faults.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sl/pipeline/synchroniser.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// Thread-compatible: one thread begins sequences, pushes and collects.
//
// One sequence is open at a time. It completes when every camera delivered
// each of its frame_count frames; the set then holds them in pattern order,
// cameras in camera_ids order, bit_depth of each camera's frame 0, stamped
// with begin()'s trigger time. Sequence ids increase from 0 per run.
class IndexedSynchroniser {
 public:
  // Throws std::invalid_argument on no cameras.
  explicit IndexedSynchroniser(std::vector<std::string> camera_ids);

  // A new run: sequence ids start again from 0; an open sequence is dropped
  // uncounted (the run it belonged to ended).
  void startRun();
  // Opens a sequence of `frame_count` frames of `pattern`. A sequence still
  // open is abandoned and counted (begin() implies it will not complete).
  // `cameras`: the indices (into camera_ids) of the cameras this sequence
  // waits for and its set holds, in camera_ids order; empty = all. Frames of
  // other cameras are counted in frames_unmatched. Throws
  // std::invalid_argument on frame_count < 1, std::out_of_range on an index
  // outside camera_ids.
  void begin(std::string pattern, int frame_count, TimestampNs trigger_stamp_ns,
             std::vector<std::size_t> cameras = {});
  // Frame `index` of the open sequence from camera `camera_index`. A frame
  // with no open sequence, an index outside it or one already delivered is
  // counted in frames_unmatched. Throws std::out_of_range on a camera index
  // outside camera_ids.
  void pushFrame(std::size_t camera_index, int index, Frame frame);
  // The open sequence will not complete: counted in triggers_incomplete when
  // `count` (a fault), dropped silently otherwise (a stop cut it short).
  void abandon(bool count);

  // Image sets completed since the last call, oldest first.
  std::vector<std::shared_ptr<const ImageSet>> takeCompleted();
  const SynchroniserCounters& counters() const { return counters_; }

 private:
  std::vector<std::string> camera_ids_;
  std::uint64_t next_sequence_id_ = 0;
  std::shared_ptr<ImageSet> open_;  // null: none open
  std::vector<std::vector<std::optional<Frame>>> frames_;  // [camera][index] of the open sequence
  std::vector<bool> expected_;  // [camera]: the open sequence waits for it
  std::size_t missing_ = 0;  // frames the open sequence still lacks
  std::vector<std::shared_ptr<const ImageSet>> completed_;
  SynchroniserCounters counters_;
};

}  // namespace sl::pipeline
