// Image sets without a trigger board: the daemon steps the projector through
// a pattern sequence itself ("project pattern i, wait, grab"), triggering
// every camera in software for each pattern, and stamps the set itself. The
// sequence rate is then bounded by settle + exposure + transfer per pattern,
// well below the hardware-triggered rate. The frames are grouped by the
// trigger-time grouping's sibling, pipeline::IndexedSynchroniser.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "sl/daemon/config.h"
#include "sl/drivers/camera.h"
#include "sl/drivers/projector.h"
#include "sl/pipeline/indexed_synchroniser.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

// Thread-compatible: one thread (the engine's control thread) acquires; the
// cameras must not be grabbed from elsewhere meanwhile.
class SoftwareTrigger {
 public:
  SoftwareTrigger(std::vector<std::shared_ptr<drivers::Camera>> cameras,
                  std::shared_ptr<drivers::Projector> projector, SoftwareTriggerConfig config);

  // Empty when the devices can be software-triggered; otherwise why not
  // (names the device).
  std::string unsupportedReason() const;

  // Acquires one sequence of `frame_count` patterns of `pattern` (selected on
  // the projector here when it changed) into `grouping`: begin() with the
  // first pattern's trigger time, then frame i of every camera as pattern i.
  // Returns false when `cancelled` turned true between patterns (the sequence
  // is left open). Throws std::runtime_error (naming the device) on a device
  // fault or an image that did not arrive within grab_timeout_s; the
  // projector is stopped then.
  // `cameras`: the indices of the cameras to trigger (empty = all); the others
  // are left alone (a simulated camera not triggered renders nothing).
  bool acquire(const std::string& pattern, int frame_count, const std::vector<std::size_t>& cameras,
               const std::function<bool()>& cancelled, pipeline::IndexedSynchroniser& grouping);

  // Ends the held pattern; the next acquire() selects its pattern again.
  void stop();

  // Frames that were taken from a camera but belonged to no trigger of ours
  // (stamped before the pattern was shown: left over from an earlier run).
  std::uint64_t staleFrames() const { return stale_frames_.load(); }  // any thread

 private:
  std::vector<std::shared_ptr<drivers::Camera>> cameras_;
  std::shared_ptr<drivers::Projector> projector_;
  const SoftwareTriggerConfig config_;
  std::string selected_;  // pattern selected on the projector by us ("" = unknown)
  std::atomic<std::uint64_t> stale_frames_{0};
};

// The control thread's side of software-triggered requests: one sequence per
// acquire(), grouped by an IndexedSynchroniser, and the fault policy (three
// failed sequences in a row end the request). Thread-compatible (the control
// thread); staleFrames() from any thread.
class SoftwareRuns {
 public:
  SoftwareRuns(std::vector<std::shared_ptr<drivers::Camera>> cameras,
               std::shared_ptr<drivers::Projector> projector, SoftwareTriggerConfig config);

  std::string unsupportedReason() const { return trigger_.unsupportedReason(); }
  // True when the run of `generation` has all of its `requested` sets (0 = continuous).
  bool finished(std::uint64_t generation, std::uint64_t requested) const {
    return requested != 0 && generation == generation_ && acquired_ >= requested;
  }

  struct Outcome {
    std::shared_ptr<const pipeline::ImageSet> set;  // null: none completed
    std::uint64_t frames = 0;  // camera frames received
    std::string fault;         // a device fault of this sequence ("" = none)
    bool end_request = false;  // the third fault in a row: end the request
  };
  // One sequence of `pattern` for the request `generation` (a new generation
  // is a new run: the pattern selected afresh, sequence ids from 0), from
  // the cameras named in `cameras` (empty = all; the set holds only them).
  // `cancelled` turning true (the request stopped) is no fault; a camera id
  // no device has is a fault of the sequence.
  Outcome acquire(std::uint64_t generation, const std::string& pattern, int frame_count,
                  const std::vector<std::string>& cameras, const std::function<bool()>& cancelled);
  // Ends the held pattern (no software run any more).
  void stop() { trigger_.stop(); }

  const pipeline::SynchroniserCounters& counters() const { return grouping_.counters(); }
  std::uint64_t staleFrames() const { return trigger_.staleFrames(); }

 private:
  SoftwareTrigger trigger_;
  pipeline::IndexedSynchroniser grouping_;
  std::vector<std::string> camera_ids_;  // of the devices, in order
  std::uint64_t generation_ = 0;  // of the run in progress
  std::uint64_t acquired_ = 0;    // its sets so far
  int failures_ = 0;              // consecutive failed sequences
};

}  // namespace sl::daemon
