#include "sl/dds/ros2_service.h"

#include <memory>
#include <vector>

namespace sl::dds {

namespace {

struct EndpointDeleter {
  void operator()(dds_builtintopic_endpoint_t* e) const { dds_builtintopic_free_endpoint(e); }
};
using Endpoint = std::unique_ptr<dds_builtintopic_endpoint_t, EndpointDeleter>;

// eProsima's RTPS vendor id, which Fast DDS puts first in every GUID prefix.
constexpr unsigned char kEprosimaVendorId[2] = {0x01, 0x0f};

}  // namespace

ServiceTopicNames serviceTopicNames(const std::string& ns, const std::string& name) {
  return {"rq/" + ns + "/" + name + "Request", "rr/" + ns + "/" + name + "Reply"};
}

std::optional<std::string> userDataValue(const dds_qos_t* qos, const std::string& key) {
  void* data = nullptr;
  size_t size = 0;
  if (qos == nullptr || !dds_qget_userdata(qos, &data, &size) || data == nullptr) return std::nullopt;
  const std::string text(static_cast<const char*>(data), size);
  dds_free(data);
  // "key=value;key=value;..."
  std::size_t at = 0;
  while (at < text.size()) {
    std::size_t end = text.find(';', at);
    if (end == std::string::npos) end = text.size();
    const std::string item = text.substr(at, end - at);
    const std::size_t eq = item.find('=');
    if (eq != std::string::npos && item.substr(0, eq) == key) return item.substr(eq + 1);
    at = end + 1;
  }
  return std::nullopt;
}

bool fromFastDds(dds_entity_t reader, dds_instance_handle_t writer) {
  const Endpoint ep(dds_get_matched_publication_data(reader, writer));
  return ep && ep->key.v[0] == kEprosimaVendorId[0] && ep->key.v[1] == kEprosimaVendorId[1];
}

ClientReader clientReader(dds_entity_t request_reader, dds_instance_handle_t request_writer,
                          dds_entity_t response_writer) {
  const Endpoint writer(dds_get_matched_publication_data(request_reader, request_writer));
  if (!writer) return ClientReader::kGone;
  const std::optional<std::string> client = userDataValue(writer->qos, "clientid");
  if (!client) return ClientReader::kMatched;  // rmw_cyclonedds: a client without an id is trusted
  std::vector<dds_instance_handle_t> readers(16);
  dds_return_t n;
  while ((n = dds_get_matched_subscriptions(response_writer, readers.data(), readers.size())) >= 0 &&
         static_cast<std::size_t>(n) > readers.size())
    readers.resize(static_cast<std::size_t>(n) + 16);
  if (n < 0) return ClientReader::kNotYet;
  for (dds_return_t i = 0; i < n; ++i) {
    const Endpoint reader(dds_get_matched_subscription_data(response_writer, readers[i]));
    if (reader && userDataValue(reader->qos, "clientid") == client) return ClientReader::kMatched;
  }
  return ClientReader::kNotYet;
}

Qos serviceRequestQos() { return Qos().reliable().keepAll().resourceLimits(256, -1, -1).xcdr1(); }

Qos serviceResponseQos() { return Qos().reliable().keepLast(64).xcdr1(); }

}  // namespace sl::dds
