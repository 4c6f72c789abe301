#include "service_bridge.h"

#include <chrono>
#include <cstdio>
#include <vector>

#include "sl/dds/malformed_samples.h"
#include "request_origin.h"
#include "sl/dds/ros2_service.h"
#include "sl/daemon/log.h"
#include "sl_msgs/srv/GetConfig.h"
#include "sl_msgs/srv/ListPatterns.h"
#include "sl_msgs/srv/SetPattern.h"
#include "sl_msgs/srv/Start.h"
#include "std_srvs/srv/Trigger.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::dds::MalformedSampleCounter;

namespace {

using StartReq = sl_msgs_srv_dds__Start_Request_;
using StartResp = sl_msgs_srv_dds__Start_Response_;
using SetPatternReq = sl_msgs_srv_dds__SetPattern_Request_;
using SetPatternResp = sl_msgs_srv_dds__SetPattern_Response_;
using ListReq = sl_msgs_srv_dds__ListPatterns_Request_;
using ListResp = sl_msgs_srv_dds__ListPatterns_Response_;
using ConfigReq = sl_msgs_srv_dds__GetConfig_Request_;
using ConfigResp = sl_msgs_srv_dds__GetConfig_Response_;
using TriggerReq = std_srvs_srv_dds__Trigger_Request_;
using TriggerResp = std_srvs_srv_dds__Trigger_Response_;

// The dispatcher's client id of a ROS 2 client: its request header's guid.
std::string clientIdOf(std::uint64_t guid) {
  char text[32];
  std::snprintf(text, sizeof text, "ros2:%016llx", static_cast<unsigned long long>(guid));
  return text;
}

std::int64_t steadyNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

struct ServiceBridge::Impl {
  Impl(const dds::Participant& participant, const std::string& ns)
      : start_malformed(dds::serviceTopicNames(ns, "start").request,
                        sl_msgs_srv_dds__Start_Request__desc.m_typename),
        stop_malformed(dds::serviceTopicNames(ns, "stop").request,
                       std_srvs_srv_dds__Trigger_Request__desc.m_typename),
        set_pattern_malformed(dds::serviceTopicNames(ns, "set_pattern").request,
                              sl_msgs_srv_dds__SetPattern_Request__desc.m_typename),
        list_malformed(dds::serviceTopicNames(ns, "list_patterns").request,
                       sl_msgs_srv_dds__ListPatterns_Request__desc.m_typename),
        config_malformed(dds::serviceTopicNames(ns, "get_config").request,
                         sl_msgs_srv_dds__GetConfig_Request__desc.m_typename),
        start(participant, ns, "start", sl_msgs_srv_dds__Start_Request__desc,
              sl_msgs_srv_dds__Start_Response__desc),
        stop(participant, ns, "stop", std_srvs_srv_dds__Trigger_Request__desc,
             std_srvs_srv_dds__Trigger_Response__desc),
        set_pattern(participant, ns, "set_pattern", sl_msgs_srv_dds__SetPattern_Request__desc,
                    sl_msgs_srv_dds__SetPattern_Response__desc),
        list_patterns(participant, ns, "list_patterns", sl_msgs_srv_dds__ListPatterns_Request__desc,
                      sl_msgs_srv_dds__ListPatterns_Response__desc),
        get_config(participant, ns, "get_config", sl_msgs_srv_dds__GetConfig_Request__desc,
                   sl_msgs_srv_dds__GetConfig_Response__desc) {}

  // Takes every waiting request of `service`: a Fast DDS-framed one is
  // counted; any other becomes a CommandRequest (`fill` sets its command and
  // fields, pointing into the request) for the dispatcher, and `respond`
  // writes the response to its reply (returns whether it was written).
  template <typename Req, typename Resp, typename Fill, typename Respond>
  void serveEach(dds::ServiceEndpoints<Req, Resp>& service, RequestDispatcher& dispatcher,
                 CommandTarget& target, Fill fill, Respond respond) {
    for (;;) {
      dds::Loan<Req> requests = service.reader().take(16);
      if (requests.empty()) return;
      for (std::size_t i = 0; i < requests.size(); ++i) {
        if (!requests.isValid(i)) continue;
        const Req& request = requests[i];
        if (dds::fromFastDds(service.reader().handle(), requests.info(i).publication_handle)) {
          if (fast_dds++ % 1000 < 10)
            logWarning("request on " + service.names().request +
                       " from a Fast DDS writer (rmw_fastrtps framing) is not served: this daemon "
                       "answers ROS 2 services in rmw_cyclonedds's framing (docs/ros2.md)");
          continue;
        }
        const std::string client_id = clientIdOf(request.request_header_guid);
        std::string empty;
        msg::Request command{};
        command.client_id = const_cast<char*>(client_id.c_str());
        command.request_id = static_cast<std::uint64_t>(request.request_header_seq);
        command.pattern = command.recording = empty.data();
        fill(request, command);
        const SenderId sender =
            origins.senderOf(service.reader().handle(), requests.info(i).publication_handle);
        const std::optional<ReplyValues> reply =
            dispatcher.dispatch(command, sender, target, steadyNs());
        if (!reply) continue;  // rate-limited: counted by the dispatcher
        dispatcher.replied(respond(request, requests.info(i), *reply));
      }
    }
  }

  MalformedSampleCounter start_malformed, stop_malformed, set_pattern_malformed, list_malformed,
      config_malformed;  // before the readers
  dds::ServiceEndpoints<StartReq, StartResp> start;
  dds::ServiceEndpoints<TriggerReq, TriggerResp> stop;
  dds::ServiceEndpoints<SetPatternReq, SetPatternResp> set_pattern;
  dds::ServiceEndpoints<ListReq, ListResp> list_patterns;
  dds::ServiceEndpoints<ConfigReq, ConfigResp> get_config;
  std::uint64_t fast_dds = 0;
  RequestOrigins origins;  // the participant of each request's writer
};

ServiceBridge::ServiceBridge(const dds::Participant& participant, const std::string& ns)
    : impl_(std::make_unique<Impl>(participant, ns)) {}
ServiceBridge::~ServiceBridge() = default;

void ServiceBridge::attach(dds::WaitSet& waitset, dds_attach_t cookie) {
  waitset.attach(impl_->start.condition(), cookie);
  waitset.attach(impl_->stop.condition(), cookie);
  waitset.attach(impl_->set_pattern.condition(), cookie);
  waitset.attach(impl_->list_patterns.condition(), cookie);
  waitset.attach(impl_->get_config.condition(), cookie);
}

std::uint64_t ServiceBridge::notServed() const {
  const Impl& d = *impl_;
  return d.fast_dds + d.start_malformed.count() + d.stop_malformed.count() +
         d.set_pattern_malformed.count() + d.list_malformed.count() + d.config_malformed.count();
}

void ServiceBridge::serve(RequestDispatcher& dispatcher, CommandTarget& target,
                          const std::string& current_pattern) {
  Impl& d = *impl_;
  // A refusal's code and text as the sl_msgs responses carry them.
  auto result = [](const ReplyValues& reply, bool& success, std::uint8_t& code, std::string& text) {
    success = reply.result.accepted();
    code = msg::toReplyCode(reply.result.code);
    text = reply.result.reason;
  };

  d.serveEach(
      d.start, dispatcher, target,
      [](const StartReq& r, msg::Request& c) {
        c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START;
        c.pattern = r.pattern;
        c.recording = r.recording;
        c.count = r.count;
        c.trigger = r.trigger;
        c.delay_s = r.delay_s;
        c.start_at = r.start_at;
        c.cameras = r.cameras;
        c.motion_compensation = r.motion_compensation;
      },
      [&](const StartReq& r, const dds_sample_info_t& info, const ReplyValues& reply) {
        StartResp response{};
        std::string message;
        result(reply, response.success, response.code, message);
        response.message = message.data();
        return d.start.respond(r, info, response);
      });

  d.serveEach(
      d.stop, dispatcher, target,
      [](const TriggerReq&, msg::Request& c) {
        c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP;
      },
      [&](const TriggerReq& r, const dds_sample_info_t& info, const ReplyValues& reply) {
        TriggerResp response{};
        std::string message = reply.result.accepted() ? "stopped" : reply.result.reason;
        response.success = reply.result.accepted();
        response.message = message.data();
        return d.stop.respond(r, info, response);
      });

  d.serveEach(
      d.set_pattern, dispatcher, target,
      [](const SetPatternReq& r, msg::Request& c) {
        c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN;
        c.pattern = r.pattern;
      },
      [&](const SetPatternReq& r, const dds_sample_info_t& info, const ReplyValues& reply) {
        SetPatternResp response{};
        std::string message;
        result(reply, response.success, response.code, message);
        response.message = message.data();
        return d.set_pattern.respond(r, info, response);
      });

  d.serveEach(
      d.list_patterns, dispatcher, target,
      [](const ListReq&, msg::Request& c) {
        c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS;
      },
      [&](const ListReq& r, const dds_sample_info_t& info, const ReplyValues& reply) {
        std::vector<std::string> names = reply.patterns;
        std::vector<char*> pointers;
        for (auto& n : names) pointers.push_back(n.data());
        std::string current = current_pattern;
        ListResp response{};
        response.patterns._buffer = pointers.data();
        response.patterns._length = response.patterns._maximum =
            static_cast<std::uint32_t>(pointers.size());
        response.patterns._release = false;
        response.current = current.data();
        return d.list_patterns.respond(r, info, response);
      });

  d.serveEach(
      d.get_config, dispatcher, target,
      [](const ConfigReq&, msg::Request& c) {
        c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_GET_CONFIG;
      },
      [&](const ConfigReq& r, const dds_sample_info_t& info, const ReplyValues& reply) {
        std::string config = reply.detail;
        ConfigResp response{};
        response.config = config.data();
        return d.get_config.respond(r, info, response);
      });
}

}  // namespace sl::daemon
