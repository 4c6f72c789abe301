#include "sl/dds/fastdds_services.h"

#include <algorithm>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <set>
#include <stdexcept>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/rtps/common/WriteParams.h>
#include <fastrtps/utils/IPLocator.h>

namespace sl::dds {

namespace {

namespace fdds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;
using Bytes = std::vector<unsigned char>;

// eProsima's RTPS vendor id, first in every Fast DDS GUID prefix.
constexpr unsigned char kEprosimaVendorId[2] = {0x01, 0x0f};
// RTPS entity kinds with this bit are readers (RTPS 2.3, 9.3.1.2); what
// rmw_fastrtps's __rmw_send_response tests to tell a response reader from a
// request writer in the related sample identity.
constexpr unsigned char kEntityIsReader = 0x04;
// The largest sample taken or written (a request over the dispatcher's
// limits is refused there, with a response).
constexpr std::uint32_t kMaxSample = 1u << 20;

// Samples as their serialized bytes (encapsulation included), unchanged.
class RawType : public fdds::TopicDataType {
 public:
  explicit RawType(const std::string& name) {
    setName(name.c_str());
    m_typeSize = 4096;  // the initial reservation: payloads grow (PREALLOCATED_WITH_REALLOC)
    m_isGetKeyDefined = false;
  }
  bool serialize(void* data, rtps::SerializedPayload_t* payload) override {
    const Bytes& b = *static_cast<Bytes*>(data);
    if (b.size() < 4 || b.size() > payload->max_size) return false;
    std::memcpy(payload->data, b.data(), b.size());
    payload->length = static_cast<std::uint32_t>(b.size());
    payload->encapsulation = b[1] == 0x01 ? CDR_LE : CDR_BE;
    return true;
  }
  bool deserialize(rtps::SerializedPayload_t* payload, void* data) override {
    if (payload->length > kMaxSample) return false;
    static_cast<Bytes*>(data)->assign(payload->data, payload->data + payload->length);
    return true;
  }
  std::function<std::uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] { return static_cast<std::uint32_t>(static_cast<Bytes*>(data)->size()); };
  }
  void* createData() override { return new Bytes(); }
  void deleteData(void* data) override { delete static_cast<Bytes*>(data); }
  bool getKey(void*, rtps::InstanceHandle_t*, bool) override { return false; }
};

Guid guidBytes(const rtps::GUID_t& g) {
  Guid out{};
  std::memcpy(out.data(), g.guidPrefix.value, 12);
  std::memcpy(out.data() + 12, g.entityId.value, 4);
  return out;
}

rtps::GUID_t guidOf(const Guid& b) {
  rtps::GUID_t g;
  std::memcpy(g.guidPrefix.value, b.data(), 12);
  std::memcpy(g.entityId.value, b.data() + 12, 4);
  return g;
}

rtps::Locator_t udpv4(const std::string& address) {
  rtps::Locator_t locator;
  locator.kind = LOCATOR_KIND_UDPv4;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(locator, address);
  locator.port = 0;  // the well-known port of the participant id
  return locator;
}

// The GUIDs an endpoint is matched with, from its listener.
class Matched {
 public:
  void change(const rtps::GUID_t& guid, int delta) {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (delta > 0) guids_.insert(guid);
      else if (delta < 0) guids_.erase(guid);
    }
    changed_.notify_all();
  }
  bool contains(const rtps::GUID_t& guid) const {
    const std::lock_guard<std::mutex> lock(mutex_);
    return guids_.count(guid) > 0;
  }
  // Waits until `guid` is matched or `until`; true if it is.
  bool waitFor(const rtps::GUID_t& guid, std::chrono::steady_clock::time_point until) {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_until(lock, until, [&] { return guids_.count(guid) > 0; });
  }

 private:
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::set<rtps::GUID_t> guids_;  // guarded by mutex_
};

class RequestListener : public fdds::DataReaderListener {
 public:
  RequestListener(Matched& writers, const std::function<void()>& on_request)
      : writers_(writers), on_request_(on_request) {}
  void on_data_available(fdds::DataReader*) override {
    if (on_request_) on_request_();
  }
  void on_subscription_matched(fdds::DataReader*, const fdds::SubscriptionMatchedStatus& s) override {
    writers_.change(rtps::iHandle2GUID(s.last_publication_handle), s.current_count_change);
  }

 private:
  Matched& writers_;
  const std::function<void()>& on_request_;
};

class ResponseListener : public fdds::DataWriterListener {
 public:
  explicit ResponseListener(Matched& readers) : readers_(readers) {}
  void on_publication_matched(fdds::DataWriter*, const fdds::PublicationMatchedStatus& s) override {
    readers_.change(rtps::iHandle2GUID(s.last_subscription_handle), s.current_count_change);
  }

 private:
  Matched& readers_;
};

struct Service {
  Service(const std::function<void()>& on_request)
      : request_listener(request_writers, on_request), response_listener(response_readers) {}
  Matched request_writers;   // writers matched by the request reader
  Matched response_readers;  // readers matched by the response writer
  RequestListener request_listener;
  ResponseListener response_listener;
  fdds::DataReader* reader = nullptr;
  fdds::DataWriter* writer = nullptr;
  std::mutex write_mutex;  // one respond() at a time per writer
};

[[noreturn]] void fail(const std::string& what) {
  throw std::runtime_error("Fast DDS services: " + what + " failed");
}

}  // namespace

std::optional<std::string> fastDdsServicesDisabled(bool cyclone_security) {
  const char* env = std::getenv("SL_FASTDDS_SERVICES");
  if (env != nullptr && std::string(env) == "0") return "SL_FASTDDS_SERVICES=0";
  if (cyclone_security)
    return "DDS Security is configured for Cyclone DDS; a Fast DDS participant would stand outside it";
  return std::nullopt;
}

struct FastDdsServices::Impl {
  std::function<void()> on_request;
  fdds::DomainParticipant* participant = nullptr;
  std::vector<std::unique_ptr<Service>> services;  // outlive the entities (deleted first)
  std::uint64_t foreign = 0;
  std::mutex take_mutex;  // guards foreign; one take() at a time

  ~Impl() {
    if (participant == nullptr) return;
    participant->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant);
  }
};

FastDdsServices::FastDdsServices(const FastDdsServiceOptions& options, std::function<void()> on_request)
    : impl_(std::make_unique<Impl>()) {
  Impl& d = *impl_;
  d.on_request = std::move(on_request);
  fdds::DomainParticipantFactory* factory = fdds::DomainParticipantFactory::get_instance();
  fdds::DomainParticipantQos qos = factory->get_default_participant_qos();
  qos.name("sl_sensord_fastdds_services");
  const std::string enclave = "enclave=/;";  // as rmw writes it
  qos.user_data().data_vec(std::vector<rtps::octet>(enclave.begin(), enclave.end()));
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  udp->interfaceWhiteList = options.ipv4_addresses;
  udp->maxInitialPeersRange = 32;
  qos.transport().use_builtin_transports = false;
  qos.transport().user_transports = {udp};
  auto& wire = qos.wire_protocol();
  if (!options.ipv4_addresses.empty()) {
    wire.builtin.metatrafficUnicastLocatorList.clear();
    wire.default_unicast_locator_list.clear();
    for (const std::string& a : options.ipv4_addresses) {
      wire.builtin.metatrafficUnicastLocatorList.push_back(udpv4(a));
      wire.default_unicast_locator_list.push_back(udpv4(a));
    }
    if (options.allow_multicast) wire.builtin.metatrafficMulticastLocatorList.push_back(udpv4("239.255.0.1"));
  }
  if (!options.ipv4_peers.empty()) {
    wire.builtin.initialPeersList.clear();
    for (const std::string& a : options.ipv4_peers) wire.builtin.initialPeersList.push_back(udpv4(a));
    if (options.allow_multicast) wire.builtin.initialPeersList.push_back(udpv4("239.255.0.1"));
  }
  d.participant = factory->create_participant(static_cast<fdds::DomainId_t>(options.domain_id), qos);
  if (d.participant == nullptr) fail("create_participant (domain " + std::to_string(options.domain_id) + ")");
  fdds::Publisher* publisher = d.participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  fdds::Subscriber* subscriber = d.participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  if (publisher == nullptr || subscriber == nullptr) fail("create_publisher/subscriber");

  // Requests: keep-all with a bound, as the Cyclone side; responses: the
  // last 64, volatile (rmw's service QoS is reliable + volatile).
  fdds::DataReaderQos rqos = fdds::DATAREADER_QOS_DEFAULT;
  rqos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  rqos.durability().kind = fdds::VOLATILE_DURABILITY_QOS;
  rqos.history().kind = fdds::KEEP_ALL_HISTORY_QOS;
  rqos.resource_limits().max_samples = 256;
  rqos.resource_limits().max_instances = 1;
  rqos.resource_limits().max_samples_per_instance = 256;
  rqos.resource_limits().allocated_samples = 16;
  rqos.endpoint().history_memory_policy = rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
  rqos.data_sharing().off();
  fdds::DataWriterQos wqos = fdds::DATAWRITER_QOS_DEFAULT;
  wqos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  wqos.durability().kind = fdds::VOLATILE_DURABILITY_QOS;
  wqos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  wqos.history().depth = 64;
  wqos.resource_limits().allocated_samples = 16;
  wqos.endpoint().history_memory_policy = rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
  wqos.data_sharing().off();

  for (const FastDdsServiceTypes& s : options.services) {
    fdds::TypeSupport request_type(new RawType(s.request_type));
    fdds::TypeSupport response_type(new RawType(s.response_type));
    if (request_type.register_type(d.participant) != ReturnCode_t::RETCODE_OK ||
        response_type.register_type(d.participant) != ReturnCode_t::RETCODE_OK)
      fail("register_type " + s.request_type);
    const std::string base = options.ns + "/" + s.name;
    fdds::Topic* rq = d.participant->create_topic("rq/" + base + "Request", s.request_type,
                                                  fdds::TOPIC_QOS_DEFAULT);
    fdds::Topic* rr = d.participant->create_topic("rr/" + base + "Reply", s.response_type,
                                                  fdds::TOPIC_QOS_DEFAULT);
    if (rq == nullptr || rr == nullptr) fail("create_topic " + base);
    auto service = std::make_unique<Service>(d.on_request);
    service->writer = publisher->create_datawriter(rr, wqos, &service->response_listener,
                                                   fdds::StatusMask::publication_matched());
    service->reader = subscriber->create_datareader(
        rq, rqos, &service->request_listener,
        fdds::StatusMask::data_available() << fdds::StatusMask::subscription_matched());
    if (service->writer == nullptr || service->reader == nullptr) fail("create_datawriter/datareader " + base);
    d.services.push_back(std::move(service));
  }
}

FastDdsServices::~FastDdsServices() = default;

std::vector<FastDdsRequest> FastDdsServices::take(std::size_t max) {
  Impl& d = *impl_;
  const std::lock_guard<std::mutex> lock(d.take_mutex);
  std::vector<FastDdsRequest> out;
  for (std::size_t i = 0; i < d.services.size() && out.size() < max; ++i) {
    Bytes sample;
    fdds::SampleInfo info;
    while (out.size() < max && d.services[i]->reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      const rtps::GUID_t& writer = info.sample_identity.writer_guid();
      if (writer.guidPrefix.value[0] != kEprosimaVendorId[0] || writer.guidPrefix.value[1] != kEprosimaVendorId[1]) {
        ++d.foreign;  // e.g. an rmw_cyclonedds client's: the Cyclone side answers it
        continue;
      }
      FastDdsRequest r;
      r.service = i;
      r.cdr = std::move(sample);
      sample = Bytes();
      r.writer = guidBytes(writer);
      const rtps::SequenceNumber_t& seq = info.sample_identity.sequence_number();
      r.sequence = (static_cast<std::int64_t>(seq.high) << 32) | seq.low;
      const rtps::GUID_t& related = info.related_sample_identity.writer_guid();
      if (related != rtps::GUID_t::unknown()) r.reply_to = guidBytes(related);
      out.push_back(std::move(r));
    }
  }
  return out;
}

bool FastDdsServices::respond(const FastDdsRequest& request, const std::vector<unsigned char>& plain_cdr,
                              std::chrono::milliseconds wait) {
  Impl& d = *impl_;
  if (request.service >= d.services.size() || plain_cdr.size() < 4) return false;
  Service& s = *d.services[request.service];
  const bool named_reader = request.reply_to != Guid{};
  const rtps::GUID_t related = guidOf(named_reader ? request.reply_to : request.writer);
  // rmw_fastrtps's __rmw_send_response: wait for a client's response reader
  // (not for a request writer named instead), and answer nothing to a
  // client whose request writer is gone.
  if (named_reader && (related.entityId.value[3] & kEntityIsReader) != 0 &&
      !s.response_readers.waitFor(related, std::chrono::steady_clock::now() + wait))
    return false;
  if (!s.request_writers.contains(guidOf(request.writer))) return false;
  rtps::WriteParams params;
  params.related_sample_identity().writer_guid(related);
  rtps::SequenceNumber_t seq;
  seq.high = static_cast<std::int32_t>(request.sequence >> 32);
  seq.low = static_cast<std::uint32_t>(request.sequence & 0xffffffffu);
  params.related_sample_identity().sequence_number(seq);
  Bytes sample = plain_cdr;
  const std::lock_guard<std::mutex> lock(s.write_mutex);
  return s.writer->write(&sample, params);
}

std::uint64_t FastDdsServices::foreign() const {
  const std::lock_guard<std::mutex> lock(impl_->take_mutex);
  return impl_->foreign;
}

}  // namespace sl::dds
