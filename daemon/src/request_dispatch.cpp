#include "request_dispatch.h"

#include <cstring>

#include "sl/daemon/log.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;

using namespace msg;

StartRequest toStartRequest(const Request& request, std::string& error) {
  StartRequest r;
  r.pattern = request.pattern ? request.pattern : "";
  r.count = request.count;
  r.recording = request.recording ? request.recording : "";
  switch (request.trigger) {
    case sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_DEFAULT: break;
    case sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_HARDWARE: r.trigger = TriggerMode::kHardware; break;
    case sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_SOFTWARE: r.trigger = TriggerMode::kSoftware; break;
    default: error = "unknown trigger mode " + std::to_string(static_cast<int>(request.trigger));
  }
  switch (request.motion_compensation) {
    case sl_msgs_msg_dds__CommandRequest_Constants_MOTION_DEFAULT: break;
    case sl_msgs_msg_dds__CommandRequest_Constants_MOTION_ON: r.motion_compensation = true; break;
    case sl_msgs_msg_dds__CommandRequest_Constants_MOTION_OFF: r.motion_compensation = false; break;
    default:
      error = "unknown motion compensation value " +
              std::to_string(static_cast<int>(request.motion_compensation));
  }
  r.delay_s = request.delay_s;
  r.start_at_ns = fromTime(request.start_at);
  r.cameras = toStrings(request.cameras);
  return r;
}

namespace {

// " count N" and the options that differ from the defaults, for the log.
std::string describeStart(const Request& request) {
  std::string text = " count " + std::to_string(request.count);
  if (request.trigger == sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_HARDWARE) text += " trigger hardware";
  if (request.trigger == sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_SOFTWARE) text += " trigger software";
  if (request.delay_s != 0) text += " delay " + std::to_string(request.delay_s) + " s";
  if (fromTime(request.start_at) != 0) text += " at " + std::to_string(fromTime(request.start_at)) + " ns";
  if (request.cameras._length > 0) {
    text += " cameras";
    for (const auto& id : toStrings(request.cameras)) text += " " + id;
  }
  if (request.motion_compensation == sl_msgs_msg_dds__CommandRequest_Constants_MOTION_ON) text += " motion on";
  if (request.motion_compensation == sl_msgs_msg_dds__CommandRequest_Constants_MOTION_OFF) text += " motion off";
  return text;
}

bool changesState(const Request& request) {
  return request.command == sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START || request.command == sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP ||
         request.command == sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN;
}

}  // namespace

CommandResult RequestDispatcher::carryOut(const Request& request, CommandTarget& target) {
  switch (request.command) {
    case sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START: {
      std::string error;
      const StartRequest start = toStartRequest(request, error);
      return error.empty() ? target.start(start)
                           : CommandResult{CommandResult::Code::kInvalidOption, error};
    }
    case sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP:
      return target.stop();
    case sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN:
      return target.selectPattern(request.pattern ? request.pattern : "");
    case sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS:
    case sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_GET_CONFIG:
      return {};  // every reply lists the patterns; the config text is the detail
    default:
      return {CommandResult::Code::kInvalidCommand,
              "unknown command " + std::to_string(static_cast<int>(request.command))};
  }
}

std::optional<ReplyValues> RequestDispatcher::dispatch(const Request& request, SenderId sender,
                                                       CommandTarget& target, std::int64_t now_ns) {
  ++guard_.counters.received;
  if (!guard_.admit(sender, now_ns)) {
    // Counted, not answered (a flood must not cost a reply each); logged at
    // most every 200 refusals.
    if (guard_.counters.rate_limited++ == rate_limited_logged_) {
      logWarning("requests over the rate limit of " + std::to_string(guard_.limits().rate_hz) +
                 "/s from the participant of client " + excerpt(request.client_id, 64) +
                 " are not answered (counted in status)");
      rate_limited_logged_ = guard_.counters.rate_limited + 200;
    }
    return std::nullopt;
  }
  // Oversized fields are refused before anything else reads them; the reply
  // and the log carry a short excerpt only.
  const std::string size_problem = guard_.checkSizes(request);
  ReplyValues reply;
  reply.client_id = request.client_id && std::strlen(request.client_id) <= guard_.limits().max_string
                        ? request.client_id
                        : excerpt(request.client_id);
  reply.request_id = request.request_id;
  const bool changes_state = changesState(request);
  const CommandResult* earlier =
      changes_state ? guard_.repeated(sender, reply.client_id, request.request_id) : nullptr;
  if (!size_problem.empty()) {
    ++guard_.counters.invalid;
    reply.result = {CommandResult::Code::kInvalidOption, size_problem};
  } else if (earlier) {
    reply.result = *earlier;  // a client's retry: the first answer again
  } else {
    reply.result = carryOut(request, target);
    if (changes_state) guard_.remember(sender, reply.client_id, request.request_id, reply.result);
  }
  static const char* kCommands[] = {"start", "stop", "set_pattern", "list_patterns", "get_config"};
  const int command = static_cast<int>(request.command);
  const std::string pattern = request.pattern ? request.pattern : "";
  if ((command < 3 || !reply.result.accepted()) && !earlier)  // queries are not worth a log line
    logInfo("request " + std::to_string(request.request_id) + " from client " +
            excerpt(request.client_id, 64) + ": " +
            (command >= 0 && command < 5 ? kCommands[command] : "unknown") +
            (pattern.empty() ? "" : " '" + excerpt(request.pattern, 64) + "'") +
            (request.command == sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START && size_problem.empty() ? describeStart(request)
                                                                                 : "") +
            (reply.result.accepted() ? ": accepted" : ": rejected: " + reply.result.reason));
  reply.patterns = target.patterns();
  if (request.command == sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_GET_CONFIG) reply.detail = target.configText();
  return reply;
}

void RequestDispatcher::replied(bool written) {
  if (written)
    ++guard_.counters.answered;
  else
    ++replies_timed_out_;
}

}  // namespace sl::daemon
