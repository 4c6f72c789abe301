#include "sl/daemon/adaptive_policy.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace sl::daemon {

const char* toString(AdaptiveMode mode) {
  switch (mode) {
    case AdaptiveMode::kStatic:
      return "static";
    case AdaptiveMode::kLinearX:
      return "linear_x";
    case AdaptiveMode::kLinearY:
      return "linear_y";
    case AdaptiveMode::kMoving:
      return "moving";
  }
  return "?";
}

namespace {

std::string format(const char* fmt, double a, double b = 0) {
  char text[160];
  std::snprintf(text, sizeof text, fmt, a, b);
  return text;
}

double norm(const std::array<double, 3>& v) {
  return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

bool isLinear(std::optional<AdaptiveMode> m) {
  return m == AdaptiveMode::kLinearX || m == AdaptiveMode::kLinearY;
}

}  // namespace

AdaptiveMode classifyMotion(const VelocitySample& velocity, const AdaptiveConfig& c,
                            std::optional<AdaptiveMode> current, std::string* reason) {
  std::string unused;
  std::string& why = reason ? *reason : unused;
  const double widen = 1 + c.hysteresis;
  const double speed = norm(velocity.linear_m_s);
  const double angular = norm(velocity.angular_rad_s);
  // The current mode's region is widened: static's limits up, linear's
  // limits up (and static's down), moving's region by linear's limits down.
  const double static_scale = current == AdaptiveMode::kStatic ? widen
                              : isLinear(current)              ? 1 / widen
                                                               : 1;
  const double limit_scale = isLinear(current)                  ? widen
                             : current == AdaptiveMode::kMoving ? 1 / widen
                                                                : 1;

  if (angular > c.max_angular_rad_s * limit_scale) {
    why = format("rotating at %.4f rad/s (max_angular_rad_s %.4g)", angular, c.max_angular_rad_s);
    return AdaptiveMode::kMoving;
  }
  if (speed <= c.static_speed_m_s * static_scale) {
    if (angular <= c.static_angular_rad_s * static_scale) {
      why = format("static: %.4f m/s, %.4f rad/s", speed, angular);
      return AdaptiveMode::kStatic;
    }
    why = format("rotating at %.4f rad/s without translation (%.4f m/s)", angular, speed);
    return AdaptiveMode::kMoving;
  }
  if (speed > c.max_speed_m_s * limit_scale) {
    why = format("too fast: %.4f m/s (max_speed_m_s %.4g)", speed, c.max_speed_m_s);
    return AdaptiveMode::kMoving;
  }
  // The dominant axis; the current linear axis keeps it until the other
  // axis is clearly faster.
  const double ax = std::abs(velocity.linear_m_s[0]);
  const double ay = std::abs(velocity.linear_m_s[1]);
  bool along_x = ax >= ay;
  if (current == AdaptiveMode::kLinearX) along_x = ax * widen >= ay;
  if (current == AdaptiveMode::kLinearY) along_x = ax > ay * widen;
  const double along = along_x ? ax : ay;
  const double off_axis = std::sqrt(std::max(0.0, speed * speed - along * along)) / speed;
  if (off_axis > c.max_off_axis * limit_scale) {
    why = format("not along x or y: %.4f m/s, %.2f of it off the axis", speed, off_axis);
    return AdaptiveMode::kMoving;
  }
  why = format(along_x ? "linear along x at %.4f m/s (%.4f rad/s)"
                       : "linear along y at %.4f m/s (%.4f rad/s)",
               speed, angular);
  return along_x ? AdaptiveMode::kLinearX : AdaptiveMode::kLinearY;
}

AdaptiveDecision AdaptivePolicy::decide(const std::optional<VelocitySample>& latest,
                                        std::int64_t now_ns) {
  AdaptiveDecision d;
  const double age_s = latest ? (now_ns - latest->received_ns) * 1e-9 : 0;
  bool urgent = false;  // switches without the dwell
  if (!latest || age_s > config_.velocity_timeout_s) {
    d.stale = true;
    d.mode = config_.safe_mode;
    d.reason = latest ? format("velocity stale: last sample %.2f s ago (velocity_timeout_s %.3g)",
                               age_s, config_.velocity_timeout_s)
                      : "no velocity received";
    urgent = true;
  } else {
    d.mode = classifyMotion(*latest, config_, current_, &d.reason);
    urgent = d.mode == AdaptiveMode::kMoving;
  }
  const bool dwelt = current_ && (now_ns - since_ns_) * 1e-9 >= config_.min_dwell_s;
  if (current_ && d.mode != *current_ && !urgent && !dwelt) {
    // Held: the current mode stays, with its reason.
    d.mode = *current_;
    d.reason = current_reason_ + " (held: min_dwell_s)";
    d.stale = false;
    return d;
  }
  d.changed = !current_ || d.mode != *current_;
  if (d.changed) {
    current_ = d.mode;
    since_ns_ = now_ns;
  }
  current_reason_ = d.reason;
  return d;
}

}  // namespace sl::daemon
