// ROS 2 services for clients on rmw_fastrtps (docs/ros2.md "ROS 2
// services"): a Fast DDS participant that serves the services' topics in
// rmw_fastrtps's framing, which Cyclone DDS 0.10 cannot write (the response
// must carry the request's id as its related sample identity, an RTPS inline
// QoS). It only moves samples: requests are handed out as plain CDR with
// their sample identity, and the caller (the daemon's ServiceBridge) parses
// them, runs them through its dispatcher and gives back the plain response.
//
// The wire, as rmw_fastrtps has it: service <ns>/<name> is the topics
// rq/<ns>/<name>Request and rr/<ns>/<name>Reply with the service's two type
// names; a request is the plain message, its id the RTPS sample identity
// (writer GUID, sequence number); its related sample identity's writer GUID
// names the client's response reader. The response is the plain message,
// written with the related sample identity = (that reader's GUID, or the
// request writer's if the client gave none; the request's sequence number),
// after waiting up to 100 ms for the response writer to match that reader.
// Only requests from Fast DDS writers (GUID prefix starting with eProsima's
// vendor id 01.0f) are taken; any other (e.g. an rmw_cyclonedds client's) is
// the Cyclone side's and dropped here. The participant's USER_DATA is
// "enclave=/;" as rmw writes it.
//
// Thread-safe: take() and respond() may run on any thread (the daemon calls
// them from its request loop); `on_request` runs on Fast DDS's threads.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace sl::dds {

struct FastDdsServiceTypes {
  std::string name;           // the service's name under the namespace, e.g. "start"
  std::string request_type;   // e.g. "sl_msgs::srv::dds_::Start_Request_"
  std::string response_type;  // e.g. "sl_msgs::srv::dds_::Start_Response_"
};

struct FastDdsServiceOptions {
  std::uint32_t domain_id = 0;
  std::string ns;  // without leading '/', e.g. "sl"
  std::vector<FastDdsServiceTypes> services;
  // UDPv4 only, bound to these addresses (the Cyclone configuration's, so
  // the two stacks are reachable on the same interfaces); empty: every
  // interface. Discovery unicast to each peer's well-known ports of
  // participant ids 0..31, plus multicast unless allow_multicast is false.
  std::vector<std::string> ipv4_addresses;
  std::vector<std::string> ipv4_peers;
  bool allow_multicast = true;
};

using Guid = std::array<unsigned char, 16>;

struct FastDdsRequest {
  std::size_t service = 0;            // index into FastDdsServiceOptions::services
  std::vector<unsigned char> cdr;     // encapsulation + plain message
  Guid writer{};                      // the request's sample identity: writer GUID,
  std::int64_t sequence = 0;          //   sequence number
  Guid reply_to{};                    // the related sample identity's writer GUID (zero: none)
};

// Whether the daemon may start its Fast DDS services: not when
// SL_FASTDDS_SERVICES=0, not when Cyclone runs DDS Security (the Fast DDS
// participant would stand outside it, unauthenticated). nullopt if it may,
// else the reason.
std::optional<std::string> fastDdsServicesDisabled(bool cyclone_security);

class FastDdsServices {
 public:
  // Throws std::runtime_error naming what Fast DDS refused.
  FastDdsServices(const FastDdsServiceOptions& options, std::function<void()> on_request);
  ~FastDdsServices();
  FastDdsServices(const FastDdsServices&) = delete;
  FastDdsServices& operator=(const FastDdsServices&) = delete;

  // Up to `max` waiting requests (of any service) from Fast DDS writers.
  std::vector<FastDdsRequest> take(std::size_t max);

  // Writes `plain_cdr` (encapsulation + plain response message) as the
  // response to `request`, once the response writer has matched the
  // client's reader (when the request named one), waiting up to `wait`.
  // False if it was not written: the reader never matched, the request's
  // writer is gone, or the write failed.
  bool respond(const FastDdsRequest& request, const std::vector<unsigned char>& plain_cdr,
               std::chrono::milliseconds wait = std::chrono::milliseconds(100));

  // Samples taken that are not Fast DDS writers' (left to the Cyclone side).
  std::uint64_t foreign() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::dds
