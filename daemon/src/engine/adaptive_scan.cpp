#include "engine/adaptive_scan.h"

#include "sl/daemon/log.h"

namespace sl::daemon {

void AdaptiveScan::setVelocity(const VelocitySample& velocity) {
  std::lock_guard lock(mutex_);
  velocity_ = velocity;
}

void AdaptiveScan::update(RequestControl& control, std::int64_t now_ns) {
  if (!config_.enabled) return;
  const RequestControl::Health health = control.health();
  const std::uint64_t generation = control.generation();
  std::unique_lock lock(mutex_);
  if (!health.scanning || health.scans_requested != 0) {
    // Adaptive scanning steers continuous scans only (a finite request
    // cannot switch pattern).
    if (generation_ != 0) {
      generation_ = 0;
      mode_.reset();
      reason_.clear();
      compensation_by_pattern_.clear();
      lock.unlock();
      control.touch();
    }
    return;
  }
  if (generation != generation_) {
    policy_.reset();
    generation_ = generation;
    mode_.reset();
    resumed_ns_ = 0;
    compensation_by_pattern_.clear();
  }
  const std::optional<VelocitySample> velocity = velocity_;
  lock.unlock();

  const AdaptiveDecision decision = policy_.decide(velocity, now_ns);
  const AdaptiveAction& action = config_.actions[static_cast<std::size_t>(decision.mode)];
  if (!decision.changed) {
    lock.lock();
    reason_ = decision.reason;  // the periodic status shows its figures
    return;
  }
  std::string error;
  if (!action.pause) {
    const CommandResult result = control.selectPattern(action.pattern);
    if (!result.accepted()) error = result.reason;
  }
  const std::string from = mode_ ? toString(*mode_) : "none";
  lock.lock();
  if (mode_ && config_.actions[static_cast<std::size_t>(*mode_)].pause && !action.pause)
    resumed_ns_ = now_ns;
  mode_ = decision.mode;
  reason_ = decision.reason;
  ++switches_;
  if (!action.pause) compensation_by_pattern_[action.pattern] = action.motion_compensation;
  lock.unlock();
  logInfo(std::string("adaptive: ") + from + " -> " + toString(decision.mode) + " (" +
          decision.reason + "): " +
          (action.pause ? std::string("paused")
                        : "pattern " + action.pattern + ", motion compensation " +
                              (action.motion_compensation ? "on" : "off")));
  if (!error.empty())
    control.reportError("adaptive: switching to " + action.pattern + ": " + error, "adaptive");
  control.touch();
}

std::optional<bool> AdaptiveScan::compensationFor(std::uint64_t generation,
                                                  const std::string& pattern) const {
  std::lock_guard lock(mutex_);
  if (generation != generation_ || generation_ == 0) return std::nullopt;
  const auto it = compensation_by_pattern_.find(pattern);
  if (it == compensation_by_pattern_.end()) return std::nullopt;
  return it->second;
}

bool AdaptiveScan::paused(std::uint64_t generation) const {
  std::lock_guard lock(mutex_);
  return generation == generation_ && generation_ != 0 && mode_ &&
         config_.actions[static_cast<std::size_t>(*mode_)].pause;
}

std::string AdaptiveScan::pauseCause(std::uint64_t generation) const {
  if (!paused(generation)) return {};
  std::lock_guard lock(mutex_);
  return std::string("paused by adaptive scanning (") + toString(*mode_) + ": " + reason_ + ")";
}

std::int64_t AdaptiveScan::resumedNs(std::uint64_t generation) const {
  std::lock_guard lock(mutex_);
  return generation == generation_ ? resumed_ns_ : 0;
}

std::optional<bool> AdaptiveScan::compensation(std::uint64_t generation) const {
  std::lock_guard lock(mutex_);
  if (generation != generation_ || generation_ == 0 || !mode_) return std::nullopt;
  const AdaptiveAction& action = config_.actions[static_cast<std::size_t>(*mode_)];
  if (action.pause) return std::nullopt;
  return action.motion_compensation;
}

void AdaptiveScan::fill(EngineStatus& s) const {
  std::lock_guard lock(mutex_);
  s.adaptive_switches = switches_;
  if (generation_ == 0 || !mode_) return;
  s.adaptive_mode = toString(*mode_);
  s.adaptive_reason = reason_;
}

}  // namespace sl::daemon
