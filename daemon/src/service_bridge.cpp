#include "service_bridge.h"

#include <chrono>
#include <cstdio>
#include <exception>
#include <vector>

#include "sl/dds/malformed_samples.h"
#include "request_origin.h"
#include "sl/dds/fastdds_services.h"
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

std::string hexOf(const dds::Guid& guid) {
  std::string text;
  char byte[3];
  for (unsigned char b : guid) {
    std::snprintf(byte, sizeof byte, "%02x", b);
    text += byte;
  }
  return text;
}

// FNV-1a over the first `n` bytes of a GUID: the 64-bit stand-in of a Fast
// DDS writer in the rmw_cyclonedds header, and of its participant (the GUID
// prefix, 12 bytes) as the dispatcher's sender.
std::uint64_t fnv(const dds::Guid& guid, std::size_t n) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (std::size_t i = 0; i < n; ++i) h = (h ^ guid[i]) * 0x100000001b3ull;
  return h;
}

// The Fast DDS participant, or null (not asked for, not built, or Fast DDS
// failed: logged).
std::unique_ptr<dds::FastDdsServices> startFastDds(const std::string& ns,
                                                   std::optional<dds::FastDdsServiceOptions> options,
                                                   dds::GuardCondition& wake) {
  if (!options) return nullptr;
#if SL_HAVE_FASTDDS
  options->ns = ns;
  options->services = {
      {"start", sl_msgs_srv_dds__Start_Request__desc.m_typename, sl_msgs_srv_dds__Start_Response__desc.m_typename},
      {"stop", std_srvs_srv_dds__Trigger_Request__desc.m_typename, std_srvs_srv_dds__Trigger_Response__desc.m_typename},
      {"set_pattern", sl_msgs_srv_dds__SetPattern_Request__desc.m_typename,
       sl_msgs_srv_dds__SetPattern_Response__desc.m_typename},
      {"list_patterns", sl_msgs_srv_dds__ListPatterns_Request__desc.m_typename,
       sl_msgs_srv_dds__ListPatterns_Response__desc.m_typename},
      {"get_config", sl_msgs_srv_dds__GetConfig_Request__desc.m_typename,
       sl_msgs_srv_dds__GetConfig_Response__desc.m_typename}};
  try {
    auto services = std::make_unique<dds::FastDdsServices>(*options, [&wake] { wake.trigger(); });
    std::string where = "every interface";
    if (!options->ipv4_addresses.empty()) {
      where.clear();
      for (const auto& a : options->ipv4_addresses) where += (where.empty() ? "" : ", ") + a;
    }
    logInfo("ROS 2 services: rmw_fastrtps clients served by a Fast DDS participant (UDPv4 on " + where + ")");
    return services;
  } catch (const std::exception& e) {
    logWarning(std::string("ROS 2 services: rmw_fastrtps clients not served: ") + e.what());
    return nullptr;
  }
#else
  (void)ns;
  (void)wake;
  logInfo("ROS 2 services: rmw_fastrtps clients not served (built without Fast DDS)");
  return nullptr;
#endif
}

// Frees a sample's contents when it goes out of scope.
struct SampleContents {
  void* sample;
  const dds_topic_descriptor_t& type;
  ~SampleContents() { dds_sample_free(sample, &type, DDS_FREE_CONTENTS); }
};

std::int64_t steadyNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

struct ServiceBridge::Impl {
  Impl(const dds::Participant& participant, const std::string& ns,
       std::optional<dds::FastDdsServiceOptions> fast_options)
      : fast_wake(participant),
        fast(startFastDds(ns, std::move(fast_options), fast_wake)),
        start_malformed(dds::serviceTopicNames(ns, "start").request,
                        sl_msgs_srv_dds__Start_Request__desc.m_typename, fast != nullptr),
        stop_malformed(dds::serviceTopicNames(ns, "stop").request,
                       std_srvs_srv_dds__Trigger_Request__desc.m_typename, fast != nullptr),
        set_pattern_malformed(dds::serviceTopicNames(ns, "set_pattern").request,
                              sl_msgs_srv_dds__SetPattern_Request__desc.m_typename, fast != nullptr),
        list_malformed(dds::serviceTopicNames(ns, "list_patterns").request,
                       sl_msgs_srv_dds__ListPatterns_Request__desc.m_typename, fast != nullptr),
        config_malformed(dds::serviceTopicNames(ns, "get_config").request,
                         sl_msgs_srv_dds__GetConfig_Request__desc.m_typename, fast != nullptr),
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

  // Runs `request` through the dispatcher as a CommandRequest (`fill` sets
  // its command and fields, pointing into the request); nullopt if it was
  // over its sender's rate (counted by the dispatcher).
  template <typename Req, typename Fill>
  std::optional<ReplyValues> dispatchOne(const Req& request, const std::string& client_id,
                                         SenderId sender, RequestDispatcher& dispatcher,
                                         CommandTarget& target, Fill fill) {
    std::string empty;
    msg::Request command{};
    command.client_id = const_cast<char*>(client_id.c_str());
    command.request_id = static_cast<std::uint64_t>(request.request_header_seq);
    command.pattern = command.recording = empty.data();
    fill(request, command);
    return dispatcher.dispatch(command, sender, target, steadyNs());
  }

  // Takes every waiting request of `service` on Cyclone: one from a Fast DDS
  // writer is left to the Fast DDS participant, or counted without it; any
  // other is dispatched, and `respond(request, reply, send)` builds the
  // response and passes it to `send` (returns whether it was written).
  template <typename Req, typename Resp, typename Fill, typename Respond>
  void serveEach(dds::ServiceEndpoints<Req, Resp>& service, RequestDispatcher& dispatcher,
                 CommandTarget& target, Fill fill, Respond respond) {
    for (;;) {
      dds::Loan<Req> requests = service.reader().take(16);
      if (requests.empty()) return;
      for (std::size_t i = 0; i < requests.size(); ++i) {
        if (!requests.isValid(i)) continue;
        const Req& request = requests[i];
        const dds_sample_info_t& info = requests.info(i);
        if (dds::fromFastDds(service.reader().handle(), info.publication_handle)) {
          if (fast) continue;  // served by the Fast DDS participant
          if (fast_dds++ % 1000 < 10)
            logWarning("request on " + service.names().request +
                       " from a Fast DDS writer (rmw_fastrtps framing) is not served: this daemon "
                       "runs without its Fast DDS participant (docs/ros2.md)");
          continue;
        }
        const SenderId sender = origins.senderOf(service.reader().handle(), info.publication_handle);
        const std::optional<ReplyValues> reply =
            dispatchOne(request, clientIdOf(request.request_header_guid), sender, dispatcher, target, fill);
        if (!reply) continue;  // rate-limited: counted by the dispatcher
        dispatcher.replied(respond(request, *reply, [&](Resp& response) {
          return service.respond(request, info, response);
        }));
      }
    }
  }

  // One request taken by the Fast DDS participant for `service`: framed as
  // rmw_cyclonedds's, parsed as Req (a sample that does not parse is counted
  // and logged), dispatched, and its response written back as plain CDR.
  template <typename Req, typename Resp, typename Fill, typename Respond>
  void serveFastDds(const dds::FastDdsRequest& taken, dds::ServiceEndpoints<Req, Resp>& service,
                    const dds_topic_descriptor_t& request_type,
                    const dds_topic_descriptor_t& response_type, RequestDispatcher& dispatcher,
                    CommandTarget& target, Fill fill, Respond respond) {
    const std::string writer = hexOf(taken.writer);
    const std::optional<dds::CdrBytes> framed =
        dds::framedFromPlainCdr(taken.cdr, fnv(taken.writer, 16), taken.sequence);
    Req request{};
    if (!framed || !dds::sampleFromCdr(*framed, &request, request_type)) {
      if (fast_malformed++ % 1000 < 10)
        logWarning("request on " + service.names().request + " from Fast DDS writer " + writer +
                   " is not a " + request_type.m_typename + " (" + std::to_string(taken.cdr.size()) +
                   " bytes): not served");
      return;
    }
    const SampleContents contents{&request, request_type};
    const std::optional<ReplyValues> reply =
        dispatchOne(request, "ros2:" + writer, fnv(taken.writer, 12), dispatcher, target, fill);
    if (!reply) return;  // rate-limited: counted by the dispatcher
    dispatcher.replied(respond(request, *reply, [&](Resp& response) {
      response.request_header_guid = request.request_header_guid;
      response.request_header_seq = request.request_header_seq;
      const std::optional<dds::CdrBytes> plain =
          dds::plainFromFramedCdr(dds::cdrFromSample(&response, response_type));
      return plain && fast->respond(taken, *plain);
    }));
  }

  dds::GuardCondition fast_wake;                // triggered by the Fast DDS participant
  std::unique_ptr<dds::FastDdsServices> fast;  // null: rmw_fastrtps clients not served
  MalformedSampleCounter start_malformed, stop_malformed, set_pattern_malformed, list_malformed,
      config_malformed;  // before the readers
  dds::ServiceEndpoints<StartReq, StartResp> start;
  dds::ServiceEndpoints<TriggerReq, TriggerResp> stop;
  dds::ServiceEndpoints<SetPatternReq, SetPatternResp> set_pattern;
  dds::ServiceEndpoints<ListReq, ListResp> list_patterns;
  dds::ServiceEndpoints<ConfigReq, ConfigResp> get_config;
  std::uint64_t fast_dds = 0;        // Fast DDS-framed on Cyclone, without the Fast DDS participant
  std::uint64_t fast_malformed = 0;  // taken by the Fast DDS participant, not parsed
  RequestOrigins origins;  // the participant of each request's writer
};

ServiceBridge::ServiceBridge(const dds::Participant& participant, const std::string& ns,
                             std::optional<dds::FastDdsServiceOptions> fast_dds)
    : impl_(std::make_unique<Impl>(participant, ns, std::move(fast_dds))) {}
ServiceBridge::~ServiceBridge() = default;

void ServiceBridge::attach(dds::WaitSet& waitset, dds_attach_t cookie) {
  waitset.attach(impl_->start.condition(), cookie);
  waitset.attach(impl_->stop.condition(), cookie);
  waitset.attach(impl_->set_pattern.condition(), cookie);
  waitset.attach(impl_->list_patterns.condition(), cookie);
  waitset.attach(impl_->get_config.condition(), cookie);
  waitset.attach(impl_->fast_wake, cookie);
}

bool ServiceBridge::servesFastDds() const { return impl_->fast != nullptr; }

std::uint64_t ServiceBridge::notServed() const {
  const Impl& d = *impl_;
  return d.fast_dds + d.fast_malformed + d.start_malformed.count() + d.stop_malformed.count() +
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

  // Per service: the CommandRequest of a request, and its response (built
  // from the dispatcher's reply and handed to `send`).
  auto start_fill = [](const StartReq& r, msg::Request& c) {
    c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START;
    c.pattern = r.pattern;
    c.recording = r.recording;
    c.count = r.count;
    c.trigger = r.trigger;
    c.delay_s = r.delay_s;
    c.start_at = r.start_at;
    c.cameras = r.cameras;
    c.motion_compensation = r.motion_compensation;
  };
  auto start_respond = [&](const StartReq&, const ReplyValues& reply, auto send) {
    StartResp response{};
    std::string message;
    result(reply, response.success, response.code, message);
    response.message = message.data();
    return send(response);
  };
  auto stop_fill = [](const TriggerReq&, msg::Request& c) {
    c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP;
  };
  auto stop_respond = [](const TriggerReq&, const ReplyValues& reply, auto send) {
    TriggerResp response{};
    std::string message = reply.result.accepted() ? "stopped" : reply.result.reason;
    response.success = reply.result.accepted();
    response.message = message.data();
    return send(response);
  };
  auto set_pattern_fill = [](const SetPatternReq& r, msg::Request& c) {
    c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN;
    c.pattern = r.pattern;
  };
  auto set_pattern_respond = [&](const SetPatternReq&, const ReplyValues& reply, auto send) {
    SetPatternResp response{};
    std::string message;
    result(reply, response.success, response.code, message);
    response.message = message.data();
    return send(response);
  };
  auto list_fill = [](const ListReq&, msg::Request& c) {
    c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS;
  };
  auto list_respond = [&](const ListReq&, const ReplyValues& reply, auto send) {
    std::vector<std::string> names = reply.patterns;
    std::vector<char*> pointers;
    for (auto& n : names) pointers.push_back(n.data());
    std::string current = current_pattern;
    ListResp response{};
    response.patterns._buffer = pointers.data();
    response.patterns._length = response.patterns._maximum = static_cast<std::uint32_t>(pointers.size());
    response.patterns._release = false;
    response.current = current.data();
    return send(response);
  };
  auto config_fill = [](const ConfigReq&, msg::Request& c) {
    c.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_GET_CONFIG;
  };
  auto config_respond = [](const ConfigReq&, const ReplyValues& reply, auto send) {
    std::string config = reply.detail;
    ConfigResp response{};
    response.config = config.data();
    return send(response);
  };

  d.serveEach(d.start, dispatcher, target, start_fill, start_respond);
  d.serveEach(d.stop, dispatcher, target, stop_fill, stop_respond);
  d.serveEach(d.set_pattern, dispatcher, target, set_pattern_fill, set_pattern_respond);
  d.serveEach(d.list_patterns, dispatcher, target, list_fill, list_respond);
  d.serveEach(d.get_config, dispatcher, target, config_fill, config_respond);

  if (!d.fast) return;
  for (;;) {
    d.fast_wake.reset();  // before taking: a request arriving later triggers it again
    const std::vector<dds::FastDdsRequest> taken = d.fast->take(16);
    if (taken.empty()) return;
    for (const dds::FastDdsRequest& r : taken) {
      switch (r.service) {  // the order of startFastDds's services
        case 0:
          d.serveFastDds(r, d.start, sl_msgs_srv_dds__Start_Request__desc, sl_msgs_srv_dds__Start_Response__desc,
                         dispatcher, target, start_fill, start_respond);
          break;
        case 1:
          d.serveFastDds(r, d.stop, std_srvs_srv_dds__Trigger_Request__desc,
                         std_srvs_srv_dds__Trigger_Response__desc, dispatcher, target, stop_fill, stop_respond);
          break;
        case 2:
          d.serveFastDds(r, d.set_pattern, sl_msgs_srv_dds__SetPattern_Request__desc,
                         sl_msgs_srv_dds__SetPattern_Response__desc, dispatcher, target, set_pattern_fill,
                         set_pattern_respond);
          break;
        case 3:
          d.serveFastDds(r, d.list_patterns, sl_msgs_srv_dds__ListPatterns_Request__desc,
                         sl_msgs_srv_dds__ListPatterns_Response__desc, dispatcher, target, list_fill,
                         list_respond);
          break;
        case 4:
          d.serveFastDds(r, d.get_config, sl_msgs_srv_dds__GetConfig_Request__desc,
                         sl_msgs_srv_dds__GetConfig_Response__desc, dispatcher, target, config_fill,
                         config_respond);
          break;
        default:
          break;
      }
    }
  }
}

}  // namespace sl::daemon
