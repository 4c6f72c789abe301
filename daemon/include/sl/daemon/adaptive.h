// Adaptive scanning (issue 33 item 4): the robot's velocity picks the
// pattern and motion compensation of a continuous scan. The value types and
// the configuration (`adaptive:`, docs/formats.md); the policy itself is
// sl/daemon/adaptive_policy.h (public: sl_eval runs it offline).
#pragma once

#include <array>
#include <cstdint>
#include <string>

namespace sl::daemon {

// What the velocity says about the motion, with the hysteresis and dwell of
// the policy applied.
enum class AdaptiveMode {
  kStatic,   // at rest: the most accurate pattern
  kLinearX,  // linear motion along the optical frame's x axis (image rows)
  kLinearY,  // linear motion along its y axis (image columns)
  kMoving,   // beyond what compensation handles: too fast, rotating, not along x or y
};
constexpr std::size_t kAdaptiveModes = 4;
// As written in the config and the status: static, linear_x, linear_y, moving.
const char* toString(AdaptiveMode mode);

// What the engine does in a mode (`adaptive.modes.<mode>`).
struct AdaptiveAction {
  bool pause = false;   // no clouds: sets are dropped, the status says why
  std::string pattern;  // the pattern switched to (unless pause)
  bool motion_compensation = false;
};

struct AdaptiveConfig {
  bool enabled = false;  // the `adaptive:` section is present
  // The robot's velocity: geometry_msgs/msg/TwistStamped on the ROS 2 topic
  // of this name (DDS topic rt/<name>, a leading '/' dropped), expressed in
  // the first camera's optical frame (x right, y down, z forward): the daemon
  // does not transform it. frame_id "" accepts any header.frame_id, else
  // samples with another one are ignored (counted in the log).
  std::string velocity_topic;
  std::string frame_id;
  // A velocity older than this (by its arrival) or none at all selects
  // safe_mode.
  double velocity_timeout_s = 0.5;
  // Static: speed and angular rate both at or below these.
  double static_speed_m_s = 0.002;
  double static_angular_rad_s = 0.01;
  // Linear: speed up to max_speed_m_s, angular rate up to max_angular_rad_s,
  // the speed off the dominant axis (x or y) at most max_off_axis of the
  // speed; anything else is kMoving.
  double max_speed_m_s = 0.1;
  double max_angular_rad_s = 0.02;
  double max_off_axis = 0.2;
  // The current mode's limits are widened by this fraction (leaving a mode
  // needs a clear change), and a mode is kept at least min_dwell_s before a
  // switch to a less tolerant one (into kMoving and safe_mode: at once).
  double hysteresis = 0.2;
  double min_dwell_s = 1.0;
  std::array<AdaptiveAction, kAdaptiveModes> actions;  // by AdaptiveMode
  AdaptiveMode safe_mode = AdaptiveMode::kMoving;      // without a fresh velocity
};

// One velocity sample as received: linear (m/s) and angular (rad/s) parts in
// the first camera's optical frame; received_ns on the steady clock.
struct VelocitySample {
  std::int64_t received_ns = 0;
  std::array<double, 3> linear_m_s{0, 0, 0};
  std::array<double, 3> angular_rad_s{0, 0, 0};
};

}  // namespace sl::daemon
