// The idlc-generated DDS types under short names, and conversions of stamps
// and string sequences; shared by the daemon's DDS edge and the client.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "builtin_interfaces/msg/Time.h"
#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/CompressedImage.h"
#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/pipeline/types.h"
#include "sl_msgs/msg/CommandReply.h"
#include "sl_msgs/msg/CommandRequest.h"
#include "sl_msgs/msg/ImageSet.h"
#include "sl_msgs/msg/ProjectorMaps.h"
#include "sl_msgs/msg/Status.h"

namespace sl::dds::msg {

using PointCloud2 = sensor_msgs_msg_dds__PointCloud2_;
using PointField = sensor_msgs_msg_dds__PointField_;
using Image = sensor_msgs_msg_dds__Image_;
using CameraInfo = sensor_msgs_msg_dds__CameraInfo_;
using CompressedImage = sensor_msgs_msg_dds__CompressedImage_;
using Request = sl_msgs_msg_dds__CommandRequest_;
using Reply = sl_msgs_msg_dds__CommandReply_;
using Status = sl_msgs_msg_dds__Status_;
using PointsReader = sl_msgs_msg_dds__PointsReader_;
using Maps = sl_msgs_msg_dds__ProjectorMaps_;
using ImageSetMsg = sl_msgs_msg_dds__ImageSet_;

constexpr std::uint8_t kFloat32 = 7;  // sensor_msgs/PointField FLOAT32

inline builtin_interfaces_msg_dds__Time_ toTime(pipeline::TimestampNs ns) {
  return {static_cast<std::int32_t>(ns / 1'000'000'000),
          static_cast<std::uint32_t>(ns % 1'000'000'000)};
}

inline pipeline::TimestampNs fromTime(const builtin_interfaces_msg_dds__Time_& t) {
  return static_cast<pipeline::TimestampNs>(t.sec) * 1'000'000'000 + t.nanosec;
}

inline std::vector<std::string> toStrings(const dds_sequence_string& seq) {
  std::vector<std::string> out;
  for (std::uint32_t i = 0; i < seq._length; ++i) out.emplace_back(seq._buffer[i]);
  return out;
}

}  // namespace sl::dds::msg
