// Image sets without a trigger board: the daemon steps the projector through
// a pattern sequence itself ("project pattern i, wait, grab"), triggering
// every camera in software for each pattern, and stamps the set itself. The
// sequence rate is then bounded by settle + exposure + transfer per pattern,
// well below the hardware-triggered rate.
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
  // the projector here when it changed). Frame i of every camera shows
  // pattern i; the set is stamped with the first pattern's trigger time.
  // Returns nullptr when `cancelled` turned true between patterns. Throws
  // std::runtime_error (naming the device) on a device fault or an image that
  // did not arrive within grab_timeout_s; the projector is stopped then.
  std::shared_ptr<const pipeline::ImageSet> acquire(const std::string& pattern, int frame_count,
                                                    const std::function<bool()>& cancelled);

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
  std::uint64_t next_sequence_id_ = 0;
  std::atomic<std::uint64_t> stale_frames_{0};
};

}  // namespace sl::daemon
