#include "sl/dds/ros2_service.h"

#include <dds/ddsi/ddsi_cdrstream.h>
#include <dds/ddsi/q_protocol.h>
#include <dds/ddsrt/endian.h>

#include <cstring>
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

constexpr std::size_t kEncapsulation = 4;  // representation id (2 bytes) + options (2 bytes)
constexpr std::size_t kHeader = 16;        // rmw_cyclonedds's guid (uint64) + seq (int64)

// Plain CDR: representation id 00 00 (big-endian) or 00 01 (little-endian).
bool plainCdr(const CdrBytes& b) {
  return b.size() >= kEncapsulation && b[0] == 0x00 && (b[1] == 0x00 || b[1] == 0x01);
}
bool bigEndian(const CdrBytes& b) { return b[1] == 0x00; }

void putU64(CdrBytes& out, std::uint64_t v, bool big_endian) {
  for (int i = 0; i < 8; ++i)
    out.push_back(static_cast<unsigned char>(v >> (big_endian ? 56 - 8 * i : 8 * i)));
}

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

std::optional<CdrBytes> framedFromPlainCdr(const CdrBytes& plain, std::uint64_t guid,
                                           std::int64_t seq) {
  if (!plainCdr(plain) || plain.size() <= kEncapsulation) return std::nullopt;
  CdrBytes framed(plain.begin(), plain.begin() + kEncapsulation);
  framed.reserve(plain.size() + kHeader);
  putU64(framed, guid, bigEndian(plain));
  putU64(framed, static_cast<std::uint64_t>(seq), bigEndian(plain));
  framed.insert(framed.end(), plain.begin() + kEncapsulation, plain.end());
  return framed;
}

std::optional<CdrBytes> plainFromFramedCdr(const CdrBytes& framed) {
  if (!plainCdr(framed) || framed.size() <= kEncapsulation + kHeader) return std::nullopt;
  CdrBytes plain(framed.begin(), framed.begin() + kEncapsulation);
  plain.insert(plain.end(), framed.begin() + kEncapsulation + kHeader, framed.end());
  return plain;
}

bool sampleFromCdr(const CdrBytes& cdr, void* sample, const dds_topic_descriptor_t& type) {
  if (!plainCdr(cdr) || cdr.size() > UINT32_MAX) return false;
  // Normalized (validated, swapped to this host's byte order) in a copy.
  std::vector<char> body(cdr.begin() + kEncapsulation, cdr.end());
  const bool swap = bigEndian(cdr) != (DDSRT_ENDIAN == DDSRT_BIG_ENDIAN);
  std::uint32_t offset = 0;
  if (dds_stream_normalize_data(body.data(), &offset, static_cast<std::uint32_t>(body.size()), swap,
                                CDR_ENC_VERSION_1, type.m_ops) == nullptr)
    return false;
  dds_istream_t in;
  dds_istream_init(&in, static_cast<std::uint32_t>(body.size()), body.data(), CDR_ENC_VERSION_1);
  dds_stream_read(&in, static_cast<char*>(sample), type.m_ops);
  dds_istream_fini(&in);
  return true;
}

CdrBytes cdrFromSample(const void* sample, const dds_topic_descriptor_t& type) {
  dds_ostream_t out;
  dds_ostream_init(&out, 0, CDR_ENC_VERSION_1);
  dds_stream_write(&out, static_cast<const char*>(sample), type.m_ops);
  CdrBytes cdr(kEncapsulation + out.m_index, 0x00);
  cdr[1] = DDSRT_ENDIAN == DDSRT_BIG_ENDIAN ? 0x00 : 0x01;
  if (out.m_index > 0) std::memcpy(cdr.data() + kEncapsulation, out.m_buffer, out.m_index);
  dds_ostream_fini(&out);
  return cdr;
}

Qos serviceRequestQos() { return Qos().reliable().keepAll().resourceLimits(256, -1, -1).xcdr1(); }

Qos serviceResponseQos() { return Qos().reliable().keepLast(64).xcdr1(); }

}  // namespace sl::dds
