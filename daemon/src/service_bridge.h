// The daemon's ROS 2 services (private to daemon/): <ns>/start
// (sl_msgs/srv/Start), <ns>/stop (std_srvs/srv/Trigger), <ns>/set_pattern,
// <ns>/list_patterns, <ns>/get_config (sl_msgs/srv), served over Cyclone DDS
// in rmw_cyclonedds's framing (ros2_service.h). Each request becomes a
// CommandRequest for the same RequestDispatcher as the command topic, so
// sizes, rate limits, retries and the status counters are the command
// topic's: every request is answered, or counted (rate-limited, reply timed
// out). The client id the dispatcher sees is "ros2:" and the request
// header's guid in hex, the request id its sequence number; the rate limit
// is the writer's participant's, shared with its command-topic requests.
//
// rmw_fastrtps clients (their request id in the RTPS sample identity, which
// Cyclone DDS cannot write into a response) are served by a Fast DDS
// participant (sl/dds/fastdds_services.h) when `fast_dds` is given: its
// plain requests are framed as rmw_cyclonedds's (framedFromPlainCdr), parsed
// by the same types and answered through the same dispatcher; the client id
// is "ros2:" and the request writer's GUID in hex, the request id its
// sequence number, the sender its participant (GUID prefix). The Cyclone
// readers then leave Fast DDS writers' samples alone (no count, no log).
// Without it, a request from a Fast DDS writer is not carried out: it is
// counted in notServed() and logged (the first 10, then every 1000th).
//
// Thread-compatible: the bridge's request loop only.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "request_dispatch.h"
#include "sl/dds/dds.h"
#include "sl/dds/fastdds_services.h"

namespace sl::daemon {

class ServiceBridge {
 public:
  // `fast_dds`: where the Fast DDS participant runs (its ns and services
  // are filled in here); nullopt, or a build without Fast DDS: none. If Fast
  // DDS fails to start, the bridge logs why and serves without it.
  ServiceBridge(const dds::Participant& participant, const std::string& ns,
                std::optional<dds::FastDdsServiceOptions> fast_dds = std::nullopt);
  ~ServiceBridge();

  // Attaches every request reader's condition to `waitset` with `cookie`.
  void attach(dds::WaitSet& waitset, dds_attach_t cookie);

  // Takes every waiting request and answers it through `dispatcher`;
  // `current_pattern` is list_patterns's `current`.
  void serve(RequestDispatcher& dispatcher, CommandTarget& target,
             const std::string& current_pattern);

  // Requests refused before the dispatcher: Fast DDS-framed without the
  // Fast DDS participant, Fast DDS requests that do not parse, plus the
  // samples Cyclone dropped as undeserializable on the request topics.
  std::uint64_t notServed() const;
  // Whether rmw_fastrtps clients are served (the Fast DDS participant runs).
  bool servesFastDds() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::daemon
