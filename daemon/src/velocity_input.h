// The robot's velocity for adaptive scanning: geometry_msgs/msg/TwistStamped
// read from the configured ROS 2 topic (adaptive.velocity_topic) and handed
// to the engine as VelocitySample (the DDS type stays at this edge).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "geometry_msgs/msg/TwistStamped.h"
#include "sl/daemon/adaptive.h"
#include "sl/daemon/scan_engine.h"
#include "sl/dds/dds.h"

namespace sl::daemon {

// The sample as the engine takes it, received at `received_ns` (steady
// clock); nullopt when `frame_id` is not empty and the header names another
// frame, or a component is not finite.
std::optional<VelocitySample> velocityOf(const geometry_msgs_msg_dds__TwistStamped_& message,
                                         const std::string& frame_id, std::int64_t received_ns);

// Thread-compatible: the DDS bridge's request loop polls it.
class VelocityInput {
 public:
  // Subscribes to rt/<config.velocity_topic> (best effort, so that reliable
  // and best-effort ROS 2 publishers both match; keep-last 1: only the
  // latest velocity matters).
  VelocityInput(const dds::Participant& participant, const AdaptiveConfig& config);
  // Takes the waiting samples and gives the newest usable one to `engine`.
  void forward(ScanEngine& engine);

 private:
  std::string frame_id_;
  dds::Topic<geometry_msgs_msg_dds__TwistStamped_> topic_;
  dds::Reader<geometry_msgs_msg_dds__TwistStamped_> reader_;
  std::uint64_t ignored_ = 0;  // samples from another frame or not finite
};

}  // namespace sl::daemon
