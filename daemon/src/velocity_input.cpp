#include "velocity_input.h"

#include <cmath>

#include "engine/device_health.h"  // steadyNowNs
#include "sl/daemon/log.h"

namespace sl::daemon {

std::optional<VelocitySample> velocityOf(const geometry_msgs_msg_dds__TwistStamped_& m,
                                         const std::string& frame_id, std::int64_t received_ns) {
  if (!frame_id.empty() && frame_id != (m.header.frame_id ? m.header.frame_id : ""))
    return std::nullopt;
  VelocitySample v;
  v.received_ns = received_ns;
  v.linear_m_s = {m.twist.linear.x, m.twist.linear.y, m.twist.linear.z};
  v.angular_rad_s = {m.twist.angular.x, m.twist.angular.y, m.twist.angular.z};
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(v.linear_m_s[i]) || !std::isfinite(v.angular_rad_s[i])) return std::nullopt;
  return v;
}

VelocityInput::VelocityInput(const dds::Participant& participant, const AdaptiveConfig& config)
    : frame_id_(config.frame_id),
      topic_(participant, "rt/" + config.velocity_topic, geometry_msgs_msg_dds__TwistStamped__desc),
      reader_(participant, topic_, dds::Qos().bestEffort().keepLast(1)) {
  logInfo("adaptive: reading the velocity from rt/" + config.velocity_topic +
          " (geometry_msgs/msg/TwistStamped)");
}

void VelocityInput::forward(ScanEngine& engine) {
  dds::Loan<geometry_msgs_msg_dds__TwistStamped_> samples = reader_.take(8);
  const std::int64_t now_ns = steadyNowNs();
  std::optional<VelocitySample> newest;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (!samples.isValid(i)) continue;
    if (std::optional<VelocitySample> v = velocityOf(samples[i], frame_id_, now_ns)) {
      newest = v;
    } else if (ignored_++ == 0) {
      logWarning("adaptive: velocity samples from frame '" +
                 std::string(samples[i].header.frame_id ? samples[i].header.frame_id : "") +
                 "' (adaptive.frame_id '" + frame_id_ + "') or not finite are ignored");
    }
  }
  if (newest) engine.setVelocity(*newest);
}

}  // namespace sl::daemon
