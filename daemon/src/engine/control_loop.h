// The scan engine's control thread: starts delayed requests and carries out
// pattern switches at their time (RequestControl::serviceTimers), and runs
// software-triggered requests, one sequence per iteration, with the camera
// threads parked meanwhile (CameraGate).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>

#include "engine/request_control.h"
#include "engine/software_trigger.h"
#include "engine/statistics.h"
#include "engine/thread_health.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

// Thread-compatible: run() on the control thread only; it owns the
// software runs while it holds the gate.
class ControlLoop {
 public:
  // Receives each software-triggered set with its request generation.
  using SetSink = std::function<void(std::uint64_t, std::shared_ptr<const pipeline::ImageSet>)>;
  ControlLoop(RequestControl& control, SoftwareRuns& software, CameraGate& gate,
              EngineStatistics& statistics, SetSink sets)
      : control_(control), software_(software), gate_(gate), statistics_(statistics), sets_(std::move(sets)) {}

  // Until `running` turns false; beats `hb` at least every 100 ms. Each
  // sequence's pattern is read at its boundary, so a switch never mixes
  // patterns within a set; the frames are grouped by the
  // IndexedSynchroniser of SoftwareRuns.
  void run(const std::atomic<bool>& running, Heartbeat& hb);

 private:
  RequestControl& control_;
  SoftwareRuns& software_;
  CameraGate& gate_;
  EngineStatistics& statistics_;
  SetSink sets_;
};

}  // namespace sl::daemon
