// Conversions between the daemon's types and the idlc-generated DDS types,
// shared by the daemon's bridge and the client (private to daemon/).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "builtin_interfaces/msg/Time.h"
#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/CompressedImage.h"
#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/daemon/commands.h"
#include "sl_msgs/msg/CommandReply.h"
#include "sl_msgs/msg/CommandRequest.h"
#include "sl_msgs/msg/ImageSet.h"
#include "sl_msgs/msg/ProjectorMaps.h"
#include "sl_msgs/msg/Status.h"

namespace sl::daemon::msg {

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

// CommandResult codes and their wire values, one row each.
inline constexpr std::array<std::pair<CommandResult::Code, std::uint8_t>, 9> kReplyCodes{{
    {CommandResult::Code::kOk, sl_msgs_msg_dds__CommandReply_Constants_REPLY_OK},
    {CommandResult::Code::kUnknownPattern, sl_msgs_msg_dds__CommandReply_Constants_REPLY_UNKNOWN_PATTERN},
    {CommandResult::Code::kBusy, sl_msgs_msg_dds__CommandReply_Constants_REPLY_BUSY},
    {CommandResult::Code::kInvalidCount, sl_msgs_msg_dds__CommandReply_Constants_REPLY_INVALID_COUNT},
    {CommandResult::Code::kInvalidCommand, sl_msgs_msg_dds__CommandReply_Constants_REPLY_INVALID_COMMAND},
    {CommandResult::Code::kDeviceError, sl_msgs_msg_dds__CommandReply_Constants_REPLY_DEVICE_ERROR},
    {CommandResult::Code::kNotRunning, sl_msgs_msg_dds__CommandReply_Constants_REPLY_NOT_RUNNING},
    {CommandResult::Code::kInvalidOption, sl_msgs_msg_dds__CommandReply_Constants_REPLY_INVALID_OPTION},
    {CommandResult::Code::kUnsupported, sl_msgs_msg_dds__CommandReply_Constants_REPLY_UNSUPPORTED},
}};

inline std::uint8_t toReplyCode(CommandResult::Code code) {
  for (const auto& [ours, wire] : kReplyCodes)
    if (ours == code) return wire;
  return sl_msgs_msg_dds__CommandReply_Constants_REPLY_INVALID_COMMAND;
}

inline CommandResult::Code fromReplyCode(std::uint8_t code) {
  for (const auto& [ours, wire] : kReplyCodes)
    if (wire == code) return ours;
  return CommandResult::Code::kInvalidCommand;  // a value this build does not know
}

inline std::vector<std::string> toStrings(const dds_sequence_string& seq) {
  std::vector<std::string> out;
  for (std::uint32_t i = 0; i < seq._length; ++i) out.emplace_back(seq._buffer[i]);
  return out;
}

}  // namespace sl::daemon::msg
