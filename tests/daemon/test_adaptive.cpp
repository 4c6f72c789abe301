// The adaptive-scanning policy (sl/daemon/adaptive_policy.h) without threads,
// clocks or DDS: velocities and times in, modes and reasons out.
#include <catch2/catch.hpp>
#include <cstdint>
#include <optional>
#include <string>

#include "sl/daemon/adaptive_policy.h"
#include "sl/daemon/adaptive.h"

using sl::daemon::AdaptiveConfig;
using sl::daemon::AdaptiveDecision;
using sl::daemon::AdaptiveMode;
using sl::daemon::AdaptivePolicy;
using sl::daemon::classifyMotion;
using sl::daemon::VelocitySample;

namespace {

constexpr std::int64_t kSecond = 1'000'000'000;

// The defaults of adaptive.h: static <= 2 mm/s and 0.01 rad/s, linear up to
// 0.1 m/s and 0.02 rad/s with at most 20 % off the axis, hysteresis 20 %,
// dwell 1 s, timeout 0.5 s, safe mode `moving`.
AdaptiveConfig defaults() {
  AdaptiveConfig c;
  c.enabled = true;
  return c;
}

VelocitySample velocity(double vx, double vy, double vz = 0, double wz = 0,
                        std::int64_t at_ns = 0) {
  VelocitySample v;
  v.received_ns = at_ns;
  v.linear_m_s = {vx, vy, vz};
  v.angular_rad_s = {0, 0, wz};
  return v;
}

}  // namespace

TEST_CASE("classifyMotion: static, linear along x or y, and beyond the limits", "[adaptive]") {
  const AdaptiveConfig c = defaults();
  std::string why;
  CHECK(classifyMotion(velocity(0, 0), c, std::nullopt, &why) == AdaptiveMode::kStatic);
  CHECK(why.rfind("static", 0) == 0);
  CHECK(classifyMotion(velocity(0.001, -0.001), c, std::nullopt) == AdaptiveMode::kStatic);
  CHECK(classifyMotion(velocity(0.06, 0.005), c, std::nullopt, &why) == AdaptiveMode::kLinearX);
  CHECK(why.find("linear along x at 0.0602 m/s") != std::string::npos);
  CHECK(classifyMotion(velocity(-0.004, -0.03), c, std::nullopt) == AdaptiveMode::kLinearY);
  // Too fast, rotating, diagonal, towards the wall: beyond compensation.
  CHECK(classifyMotion(velocity(0.15, 0), c, std::nullopt, &why) == AdaptiveMode::kMoving);
  CHECK(why.find("too fast") != std::string::npos);
  CHECK(classifyMotion(velocity(0.05, 0, 0, 0.1), c, std::nullopt, &why) == AdaptiveMode::kMoving);
  CHECK(why.find("rotating") != std::string::npos);
  CHECK(classifyMotion(velocity(0, 0, 0, 0.015), c, std::nullopt, &why) == AdaptiveMode::kMoving);
  CHECK(why.find("without translation") != std::string::npos);
  CHECK(classifyMotion(velocity(0.04, 0.04), c, std::nullopt, &why) == AdaptiveMode::kMoving);
  CHECK(why.find("not along x or y") != std::string::npos);
  CHECK(classifyMotion(velocity(0, 0, 0.05), c, std::nullopt) == AdaptiveMode::kMoving);
}

TEST_CASE("classifyMotion: the current mode's region is widened by the hysteresis", "[adaptive]") {
  const AdaptiveConfig c = defaults();  // hysteresis 0.2
  // 2.2 mm/s: beyond static's 2 mm/s, within 2 * 1.2 = 2.4 mm/s.
  const VelocitySample slow = velocity(0.0022, 0);
  CHECK(classifyMotion(slow, c, std::nullopt) == AdaptiveMode::kLinearX);
  CHECK(classifyMotion(slow, c, AdaptiveMode::kStatic) == AdaptiveMode::kStatic);
  // 1.8 mm/s: static from anywhere but linear (2 / 1.2 = 1.67 mm/s there).
  CHECK(classifyMotion(velocity(0.0018, 0), c, AdaptiveMode::kMoving) == AdaptiveMode::kStatic);
  CHECK(classifyMotion(velocity(0.0018, 0), c, AdaptiveMode::kLinearX) == AdaptiveMode::kLinearX);
  // 0.11 m/s: too fast, unless already linear (0.12 there).
  CHECK(classifyMotion(velocity(0.11, 0), c, std::nullopt) == AdaptiveMode::kMoving);
  CHECK(classifyMotion(velocity(0.11, 0), c, AdaptiveMode::kLinearX) == AdaptiveMode::kLinearX);
  // 0.09 m/s: linear, but from moving it must come below 0.1 / 1.2.
  CHECK(classifyMotion(velocity(0.09, 0), c, AdaptiveMode::kMoving) == AdaptiveMode::kMoving);
  CHECK(classifyMotion(velocity(0.08, 0), c, AdaptiveMode::kMoving) == AdaptiveMode::kLinearX);
  // The axis: y slightly faster than x keeps linear_x, clearly faster switches.
  CHECK(classifyMotion(velocity(0.030, 0.033), c, AdaptiveMode::kLinearX, nullptr) !=
        AdaptiveMode::kLinearY);
  CHECK(classifyMotion(velocity(0.001, 0.05), c, AdaptiveMode::kLinearX) == AdaptiveMode::kLinearY);
}

TEST_CASE("AdaptivePolicy: switches, dwell, and the safe mode without a fresh velocity",
          "[adaptive]") {
  AdaptiveConfig c = defaults();
  c.safe_mode = AdaptiveMode::kStatic;  // a stale velocity: this mode
  AdaptivePolicy policy(c);

  // No velocity yet: the safe mode, as a switch (the first decision).
  AdaptiveDecision d = policy.decide(std::nullopt, 0);
  CHECK(d.changed);
  CHECK(d.stale);
  CHECK(d.mode == AdaptiveMode::kStatic);
  CHECK(d.reason == "no velocity received");

  // At rest: static, no switch.
  d = policy.decide(velocity(0, 0, 0, 0, kSecond / 10), kSecond / 10 + 1);
  CHECK_FALSE(d.changed);
  CHECK_FALSE(d.stale);
  CHECK(d.mode == AdaptiveMode::kStatic);

  // Linear motion 0.5 s after the first switch: held by the dwell (1 s).
  d = policy.decide(velocity(0.06, 0, 0, 0, kSecond / 2), kSecond / 2);
  CHECK_FALSE(d.changed);
  CHECK(d.mode == AdaptiveMode::kStatic);
  CHECK(d.reason.find("held") != std::string::npos);
  // After the dwell: linear_x.
  d = policy.decide(velocity(0.06, 0, 0, 0, kSecond), kSecond + 1);
  CHECK(d.changed);
  CHECK(d.mode == AdaptiveMode::kLinearX);

  // Rotation right after: into `moving` at once, no dwell.
  d = policy.decide(velocity(0.06, 0, 0, 0.2, kSecond + kSecond / 10), kSecond + kSecond / 10);
  CHECK(d.changed);
  CHECK(d.mode == AdaptiveMode::kMoving);
  CHECK(d.reason.find("rotating at 0.2000 rad/s") != std::string::npos);
  // Back to linear within the dwell: held in `moving`.
  d = policy.decide(velocity(0.06, 0, 0, 0, kSecond + kSecond / 5), kSecond + kSecond / 5);
  CHECK_FALSE(d.changed);
  CHECK(d.mode == AdaptiveMode::kMoving);

  // The velocity stops coming: 0.5 s after the last sample it is still
  // fresh, beyond that stale: the safe mode at once, with the age.
  const std::int64_t last = kSecond + kSecond / 5;
  CHECK_FALSE(policy.decide(velocity(0.06, 0, 0, 0, last), last + kSecond / 2).stale);
  d = policy.decide(velocity(0.06, 0, 0, 0, last), last + kSecond / 2 + kSecond / 10);
  CHECK(d.stale);
  CHECK(d.changed);
  CHECK(d.mode == AdaptiveMode::kStatic);
  CHECK(d.reason.find("velocity stale: last sample 0.60 s ago") != std::string::npos);
  CHECK(policy.mode() == AdaptiveMode::kStatic);

  // A new scan: the first decision switches again.
  policy.reset();
  CHECK_FALSE(policy.mode().has_value());
  d = policy.decide(velocity(0, 0.05, 0, 0, 10 * kSecond), 10 * kSecond);
  CHECK(d.changed);
  CHECK(d.mode == AdaptiveMode::kLinearY);
}

TEST_CASE("AdaptivePolicy: a velocity flapping around a threshold does not flap the mode",
          "[adaptive]") {
  AdaptiveConfig c = defaults();
  c.hysteresis = 0;  // the dwell alone bounds the switches
  c.min_dwell_s = 1.0;
  AdaptivePolicy policy(c);
  int switches = 0;
  // 10 s at 20 Hz, the speed alternating each sample between 1.9 and 2.1 mm/s.
  for (int i = 0; i < 200; ++i) {
    const std::int64_t t = i * kSecond / 20;
    const double v = i % 2 ? 0.0021 : 0.0019;
    if (policy.decide(velocity(v, 0, 0, 0, t), t).changed) ++switches;
  }
  // At most one switch per dwell (and the first decision).
  CHECK(switches <= 11);
  CHECK(switches >= 2);

  // With the hysteresis, the same velocity stays in its first mode.
  c.hysteresis = 0.2;
  AdaptivePolicy steady(c);
  switches = 0;
  for (int i = 0; i < 200; ++i) {
    const std::int64_t t = i * kSecond / 20;
    const double v = i % 2 ? 0.0021 : 0.0019;
    if (steady.decide(velocity(v, 0, 0, 0, t), t).changed) ++switches;
  }
  CHECK(switches == 1);
}
