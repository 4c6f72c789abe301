// A ROS 2 service client in the framing of rmw_fastrtps (docs/ros2.md): the
// plain request message on rq/<ns>/<name>Request, written with the related
// sample identity's writer GUID set to the client's response reader, as
// rmw_fastrtps_shared_cpp's __rmw_send_request does; a response counts only
// if its related sample identity names that reader (the client's filter).
// The request bytes are given as hex (4-byte encapsulation + message, e.g.
// from Foxglove's serializer) and sent through a raw type, so nothing here
// comes from the daemon's types.
//
// usage: fastdds_service_client DOMAIN NAMESPACE SERVICE TYPE HEX WAIT_S
//   TYPE: the DDS type name without _Request_/_Response_, e.g.
//   sl_msgs::srv::dds_::ListPatterns_
// Prints "fast_dds_server 1" if a Fast DDS request reader and response
// writer matched within 10 s (else 0, and the request goes to whatever
// matched), "responses N" (responses for this client within WAIT_S) and, for
// each, "response HEX". Exit 0 unless Fast DDS failed.
// Fast DDS is configured from FASTRTPS_DEFAULT_PROFILES_FILE (e.g.
// config/fastdds-loopback.xml).
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastrtps/rtps/common/WriteParams.h>

namespace {

namespace fdds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;
using Bytes = std::vector<unsigned char>;

// Samples as their serialized bytes (encapsulation included), unchanged.
class RawType : public fdds::TopicDataType {
 public:
  explicit RawType(const std::string& name) {
    setName(name.c_str());
    m_typeSize = 1u << 20;
    m_isGetKeyDefined = false;
  }
  bool serialize(void* data, rtps::SerializedPayload_t* payload) override {
    const Bytes& b = *static_cast<Bytes*>(data);
    if (b.size() < 4 || b.size() > payload->max_size) return false;
    std::memcpy(payload->data, b.data(), b.size());
    payload->length = static_cast<uint32_t>(b.size());
    payload->encapsulation = b[1] == 0x01 ? CDR_LE : CDR_BE;
    return true;
  }
  bool deserialize(rtps::SerializedPayload_t* payload, void* data) override {
    static_cast<Bytes*>(data)->assign(payload->data, payload->data + payload->length);
    return true;
  }
  std::function<uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] { return static_cast<uint32_t>(static_cast<Bytes*>(data)->size()); };
  }
  void* createData() override { return new Bytes(); }
  void deleteData(void* data) override { delete static_cast<Bytes*>(data); }
  bool getKey(void*, rtps::InstanceHandle_t*, bool) override { return false; }
};

std::string toHex(const Bytes& b) {
  static const char* digits = "0123456789abcdef";
  std::string hex;
  for (unsigned char c : b) {
    hex += digits[c >> 4];
    hex += digits[c & 15];
  }
  return hex;
}

// Whether an endpoint matched one of a Fast DDS participant (GUID prefix
// starting with eProsima's vendor id 01.0f), as the daemon's Fast DDS
// service endpoints are; the daemon's Cyclone endpoints match too, and
// would answer nothing this client takes.
bool fastDdsGuid(const fdds::InstanceHandle_t& handle) {
  const rtps::GUID_t guid = rtps::iHandle2GUID(handle);
  return guid.guidPrefix.value[0] == 0x01 && guid.guidPrefix.value[1] == 0x0f;
}

struct WriterMatch : fdds::DataWriterListener {
  std::atomic<int> fast_dds{0};
  void on_publication_matched(fdds::DataWriter*, const fdds::PublicationMatchedStatus& s) override {
    if (fastDdsGuid(s.last_subscription_handle)) fast_dds += s.current_count_change;
  }
};

struct ReaderMatch : fdds::DataReaderListener {
  std::atomic<int> fast_dds{0};
  void on_subscription_matched(fdds::DataReader*, const fdds::SubscriptionMatchedStatus& s) override {
    if (fastDdsGuid(s.last_publication_handle)) fast_dds += s.current_count_change;
  }
};

struct ParticipantGuard {
  fdds::DomainParticipant* p = nullptr;
  ~ParticipantGuard() {
    if (p) {
      p->delete_contained_entities();
      fdds::DomainParticipantFactory::get_instance()->delete_participant(p);
    }
  }
};

int fail(const char* what) {
  std::fprintf(stderr, "fastdds_service_client: %s failed\n", what);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 7) {
    std::fprintf(stderr, "usage: fastdds_service_client DOMAIN NAMESPACE SERVICE TYPE HEX WAIT_S\n");
    return 2;
  }
  const int domain = std::atoi(argv[1]);
  const std::string ns = argv[2], service = argv[3], type = argv[4], hex = argv[5];
  const double wait_s = std::atof(argv[6]);
  Bytes request;
  for (std::size_t i = 0; i + 1 < hex.size(); i += 2)
    request.push_back(static_cast<unsigned char>(std::stoi(hex.substr(i, 2), nullptr, 16)));

  ParticipantGuard guard;
  guard.p = fdds::DomainParticipantFactory::get_instance()->create_participant(
      domain, fdds::PARTICIPANT_QOS_DEFAULT);
  if (!guard.p) return fail("create_participant");
  const std::string base = type.substr(0, type.size() - 1);  // without the trailing '_'
  fdds::TypeSupport request_type(new RawType(base + "_Request_"));
  fdds::TypeSupport response_type(new RawType(base + "_Response_"));
  if (request_type.register_type(guard.p) != ReturnCode_t::RETCODE_OK ||
      response_type.register_type(guard.p) != ReturnCode_t::RETCODE_OK)
    return fail("register_type");
  fdds::Topic* rq = guard.p->create_topic("rq/" + ns + "/" + service + "Request",
                                          request_type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
  fdds::Topic* rr = guard.p->create_topic("rr/" + ns + "/" + service + "Reply",
                                          response_type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
  if (!rq || !rr) return fail("create_topic");
  fdds::Publisher* publisher = guard.p->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  fdds::Subscriber* subscriber = guard.p->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  if (!publisher || !subscriber) return fail("create_publisher/subscriber");
  // rmw's default service QoS: reliable, volatile, keep last 10.
  fdds::DataWriterQos wqos = fdds::DATAWRITER_QOS_DEFAULT;
  wqos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  wqos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  wqos.history().depth = 10;
  fdds::DataReaderQos rqos = fdds::DATAREADER_QOS_DEFAULT;
  rqos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  rqos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  rqos.history().depth = 10;
  WriterMatch writer_match;
  ReaderMatch reader_match;
  fdds::DataWriter* writer = publisher->create_datawriter(rq, wqos, &writer_match);
  fdds::DataReader* reader = subscriber->create_datareader(rr, rqos, &reader_match);
  if (!writer || !reader) return fail("create_datawriter/datareader");

  // Wait until a Fast DDS request reader and response writer are matched
  // (rcl's service_server_is_available asks the same of the graph). None
  // within 10 s: "fast_dds_server 0", and the request is sent anyway.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while ((writer_match.fast_dds <= 0 || reader_match.fast_dds <= 0) &&
         std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const bool server = writer_match.fast_dds > 0 && reader_match.fast_dds > 0;
  std::printf("fast_dds_server %d\n", server ? 1 : 0);
  if (!server) {
    // Something to send to: the daemon's Cyclone endpoints at least.
    fdds::PublicationMatchedStatus pm;
    writer->get_publication_matched_status(pm);
    if (pm.current_count == 0) return fail("matching the daemon's service");
  }

  rtps::WriteParams params;
  params.related_sample_identity().writer_guid() = reader->guid();
  if (!writer->write(&request, params)) return fail("write");
  const rtps::SequenceNumber_t sent = params.sample_identity().sequence_number();

  std::vector<Bytes> responses;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
  while (std::chrono::steady_clock::now() < end) {
    Bytes sample;
    fdds::SampleInfo info;
    while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      // rmw_fastrtps's ClientListener: the response names this client's
      // reader (or writer) in its related sample identity.
      const auto& related = info.related_sample_identity;
      if ((related.writer_guid() == reader->guid() || related.writer_guid() == writer->guid()) &&
          related.sequence_number() == sent)
        responses.push_back(sample);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::printf("responses %zu\n", responses.size());
  for (const auto& r : responses) std::printf("response %s\n", toHex(r).c_str());
  return 0;
}
