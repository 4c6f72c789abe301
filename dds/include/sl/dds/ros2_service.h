// ROS 2 services over Cyclone DDS, framed as rmw_cyclonedds frames them
// (docs/ros2.md "ROS 2 services", with the sources): service <ns>/<name> is
// the topics rq/<ns>/<name>Request and rr/<ns>/<name>Reply; each request and
// response sample starts with the request header (the client's id, the
// request's sequence number), which the response copies from its request;
// a client takes the responses that carry its id.
//
// ServiceEndpoints is the server side of one service: the request reader, the
// response writer, and the wait for the client's response reader that
// rmw_cyclonedds does before it answers. Req and Resp are idlc types whose
// first two members are the header (idl/ros2_to_dds_idl.py
// --cyclonedds-request-header: request_header_guid, request_header_seq).
//
// rmw_fastrtps frames services differently (the ids in the RTPS sample
// identity, the plain message as payload), which a Cyclone DDS writer cannot
// produce: requests from Fast DDS writers are recognised by their GUID
// (fromFastDds) and left to the daemon's Fast DDS participant
// (fastdds_services.h), whose plain samples framedFromPlainCdr /
// plainFromFramedCdr convert to and from this framing, so that one parser
// (sampleFromCdr) and one serializer (cdrFromSample) serve both.
//
// Thread-compatible, like the dds:: wrappers it holds.
#pragma once

#include <dds/dds.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "sl/dds/dds.h"

namespace sl::dds {

struct ServiceTopicNames {
  std::string request;  // rq/<ns>/<name>Request
  std::string reply;    // rr/<ns>/<name>Reply
};
ServiceTopicNames serviceTopicNames(const std::string& ns, const std::string& name);

// The value of `key` in a USER_DATA "key=value;..." list as rmw_cyclonedds
// writes it (clientid=...;), or nullopt.
std::optional<std::string> userDataValue(const dds_qos_t* qos, const std::string& key);

// Whether the writer `writer` matched by `reader` is a Fast DDS entity: Fast
// DDS starts every GUID prefix with eProsima's vendor id 0x01 0x0f. False if
// the writer is not (or no longer) matched.
bool fromFastDds(dds_entity_t reader, dds_instance_handle_t writer);

// Where the response to a request written by `request_writer` (as matched by
// the service's request reader) can go: rmw_cyclonedds's
// check_for_response_reader. kMatched: the response writer has matched a
// reader of the same client (the same USER_DATA clientid as the request's
// writer; a writer without one is taken as matched); kNotYet: the request's
// writer is there, its client's reader not (yet); kGone: the request's
// writer is gone.
enum class ClientReader { kMatched, kNotYet, kGone };
ClientReader clientReader(dds_entity_t request_reader, dds_instance_handle_t request_writer,
                          dds_entity_t response_writer);

// A serialized sample: the 4-byte encapsulation (plain CDR, XCDR1: 00 00
// big-endian or 00 01 little-endian, then 2 option bytes) and the message.
using CdrBytes = std::vector<unsigned char>;

// rmw_fastrtps's plain request or response to rmw_cyclonedds's framing: the
// header (guid, seq: 16 bytes in the encapsulation's byte order) inserted
// after the encapsulation. The header keeps every later field's CDR
// alignment (16 is a multiple of 8). nullopt if `plain` has no plain-CDR
// encapsulation or no message byte after it.
std::optional<CdrBytes> framedFromPlainCdr(const CdrBytes& plain, std::uint64_t guid,
                                           std::int64_t seq);
// The reverse: the header removed. nullopt if `framed` has no plain-CDR
// encapsulation or is not longer than encapsulation + header.
std::optional<CdrBytes> plainFromFramedCdr(const CdrBytes& framed);

// `cdr` (plain CDR, either byte order) into `sample`, a zeroed sample of
// `type` (free it with dds_sample_free(..., DDS_FREE_CONTENTS) whatever the
// result). False, leaving nothing to free, if the bytes are not a valid
// `type` (truncated, a bool or enum out of range, a bound exceeded):
// Cyclone's own validation (dds_stream_normalize_data) runs first.
bool sampleFromCdr(const CdrBytes& cdr, void* sample, const dds_topic_descriptor_t& type);
// `sample` of `type` as plain CDR in this host's byte order.
CdrBytes cdrFromSample(const void* sample, const dds_topic_descriptor_t& type);

// QoS of both endpoints: reliable, XCDR1; the request reader keeps every
// request up to a bound (a flood is held back by the reliable protocol, as on
// the command topic), the response writer keeps the last 64 responses.
Qos serviceRequestQos();
Qos serviceResponseQos();

template <typename Req, typename Resp>
class ServiceEndpoints {
 public:
  ServiceEndpoints(const Participant& participant, const std::string& ns, const std::string& name,
                   const dds_topic_descriptor_t& request_type,
                   const dds_topic_descriptor_t& response_type)
      : names_(serviceTopicNames(ns, name)),
        request_topic_(participant, names_.request, request_type),
        response_topic_(participant, names_.reply, response_type),
        reader_(participant, request_topic_, serviceRequestQos()),
        writer_(participant, response_topic_, serviceResponseQos()),
        condition_(reader_) {}

  const ServiceTopicNames& names() const { return names_; }
  Reader<Req>& reader() { return reader_; }
  const ReadCondition& condition() const { return condition_; }

  // Writes `response` (its header copied from `request`) once the client's
  // response reader is matched, waiting up to `wait` for it as rmw_cyclonedds
  // does (100 ms). False if it was not written: the client's reader never
  // matched, its request writer is gone, or the reliable write timed out.
  bool respond(const Req& request, const dds_sample_info_t& info, Resp& response,
               dds_duration_t wait = DDS_MSECS(100)) {
    response.request_header_guid = request.request_header_guid;
    response.request_header_seq = request.request_header_seq;
    const dds_time_t end = dds_time() + wait;
    ClientReader state;
    while ((state = clientReader(reader_.handle(), info.publication_handle, writer_.handle())) ==
               ClientReader::kNotYet &&
           dds_time() < end)
      dds_sleepfor(DDS_MSECS(5));
    return state == ClientReader::kMatched && writer_.write(response);
  }

 private:
  ServiceTopicNames names_;
  Topic<Req> request_topic_;
  Topic<Resp> response_topic_;
  Reader<Req> reader_;
  Writer<Resp> writer_;
  ReadCondition condition_;
};

}  // namespace sl::dds
