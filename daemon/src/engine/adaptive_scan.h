// Adaptive scanning in the engine (issue 33 item 4): keeps the robot's
// latest velocity, runs the policy (sl/daemon/adaptive_policy.h) for the
// continuous scan in progress and carries out its switches through request
// control's public API (selectPattern: at the next sequence boundary, as a
// client's SET_PATTERN), and tells the processing thread which compensation
// each pattern's sets get and whether clouds are paused.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>

#include "sl/daemon/adaptive_policy.h"
#include "engine/request_control.h"
#include "sl/daemon/adaptive.h"
#include "sl/daemon/scan_engine.h"

namespace sl::daemon {

// Thread-safe: setVelocity from any thread, update() from one thread (the
// engine's output thread), the queries from any.
class AdaptiveScan {
 public:
  explicit AdaptiveScan(const AdaptiveConfig& config) : config_(config), policy_(config) {}

  bool enabled() const { return config_.enabled; }
  void setVelocity(const VelocitySample& velocity);
  // Runs the policy for the running request (a continuous scan only; a new
  // request starts the policy afresh) and applies a switch: the mode's
  // pattern via control.selectPattern, its compensation, or a pause. Every
  // switch is logged and counted. Call periodically (every ~100 ms).
  void update(RequestControl& control, std::int64_t now_ns);

  // What the processing thread applies to a set of `generation` with
  // `pattern`: nullopt = adaptive has no say (off, another request, a
  // pattern no applied mode uses), else the mode's compensation.
  std::optional<bool> compensationFor(std::uint64_t generation, const std::string& pattern) const;
  // True while the mode of `generation` pauses: its sets are dropped.
  bool paused(std::uint64_t generation) const;
  // Degraded cause while paused ("" = not paused).
  std::string pauseCause(std::uint64_t generation) const;
  // When `generation` last left a paused mode (steady clock ns; 0 = never):
  // the stall check counts from there.
  std::int64_t resumedNs(std::uint64_t generation) const;
  // The current mode's compensation while it applies (for the status).
  std::optional<bool> compensation(std::uint64_t generation) const;
  void fill(EngineStatus& status) const;

 private:
  const AdaptiveConfig config_;
  AdaptivePolicy policy_;  // update() only

  mutable std::mutex mutex_;
  std::optional<VelocitySample> velocity_;  // guarded by mutex_
  // The request the policy runs for (0 = none), its mode and why; guarded by mutex_.
  std::uint64_t generation_ = 0;
  std::optional<AdaptiveMode> mode_;
  std::string reason_;
  std::uint64_t switches_ = 0;
  std::int64_t resumed_ns_ = 0;
  // Compensation by pattern of the modes applied during generation_: sets
  // of the previous mode's pattern still in flight keep their mode's.
  std::map<std::string, bool> compensation_by_pattern_;
};

}  // namespace sl::daemon
