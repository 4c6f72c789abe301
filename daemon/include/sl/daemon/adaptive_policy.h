// The adaptive-scanning policy (issue 33 item 4): from the latest velocity,
// the time and the current mode, the mode to scan in and why. Pure: no
// threads, no clocks, no DDS; the engine calls decide() periodically while
// a continuous scan runs and carries out the switches it reports.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "sl/daemon/adaptive.h"

namespace sl::daemon {

struct AdaptiveDecision {
  AdaptiveMode mode = AdaptiveMode::kStatic;
  std::string reason;    // why `mode`, with the figures that decided it
  bool changed = false;  // a switch: the first decision, or another mode than before
  bool stale = false;    // no fresh velocity: `mode` is the safe mode
};

// The mode `velocity` calls for, `current` widened by the hysteresis (no
// current mode: none widened); `reason` says why. Ignores staleness and dwell.
AdaptiveMode classifyMotion(const VelocitySample& velocity, const AdaptiveConfig& config,
                            std::optional<AdaptiveMode> current, std::string* reason = nullptr);

// Thread-compatible. Times are nanoseconds on one monotonic clock (the
// engine's steady clock), the same as VelocitySample::received_ns.
class AdaptivePolicy {
 public:
  explicit AdaptivePolicy(const AdaptiveConfig& config) : config_(config) {}

  // The mode for `now_ns` given the latest velocity received (nullopt: none
  // yet). A velocity older than velocity_timeout_s selects the safe mode at
  // once; so does a switch into kMoving. Other switches wait until the
  // current mode has been held min_dwell_s. The first decision after
  // construction or reset() always switches.
  AdaptiveDecision decide(const std::optional<VelocitySample>& latest, std::int64_t now_ns);
  // Forgets the current mode (a new scan starts).
  void reset() { current_.reset(); }
  std::optional<AdaptiveMode> mode() const { return current_; }

 private:
  const AdaptiveConfig config_;
  std::optional<AdaptiveMode> current_;
  std::string current_reason_;
  std::int64_t since_ns_ = 0;  // when current_ was entered
};

}  // namespace sl::daemon
