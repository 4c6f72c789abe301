// CommandResult codes and their wire values (sl_msgs/CommandReply REPLY_*),
// one row each; shared by the daemon's request dispatch and SensorClient.
#pragma once

#include <array>
#include <cstdint>
#include <utility>

#include "sl/client/commands.h"
#include "sl_msgs/msg/CommandReply.h"

namespace sl::client {

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

}  // namespace sl::client
