// The daemon's side of the sl_msgs wire check (tools/sl_view/test/sl_msgs_wire.mjs):
// reads lines "TYPE HEX" (TYPE e.g. sl_msgs/msg/Status or
// sl_msgs/srv/Start_Request, HEX a serialized sample with its 4-byte
// encapsulation header) and answers each with "TYPE HEX DDS_TYPE_NAME": the sample taken
// by a Cyclone DDS reader of the daemon's type (sl_idl, generated from
// ros2/sl_msgs), written again by a writer of that type, as serialized on
// the wire. A sample Cyclone refuses to deserialize, or a type this program
// does not know, is an error line "TYPE ERROR why" and exit status 1.
//
// Every sample goes through a real writer and reader (unique topic per type
// and run) in one participant: the serialization is the one dds_write gives
// the daemon's samples.
#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>
#include <unistd.h>

#include "sl_msgs/msg/CommandReply.h"
#include "sl_msgs/msg/CommandRequest.h"
#include "sl_msgs/msg/ImageSet.h"
#include "sl_msgs/msg/PointsReader.h"
#include "sl_msgs/msg/ProjectorMaps.h"
#include "sl_msgs/msg/Status.h"
#include "sl_msgs/srv/GetConfig.h"
#include "sl_msgs/srv/ListPatterns.h"
#include "sl_msgs/srv/SetPattern.h"
#include "sl_msgs/srv/Start.h"
#include "std_srvs/srv/Trigger.h"

namespace {

// Every type of ros2/sl_msgs and idl/std_srvs; sl_msgs_wire.mjs fails when
// a package has one this table lacks.
const std::map<std::string, const dds_topic_descriptor_t*>& descriptors() {
  static const std::map<std::string, const dds_topic_descriptor_t*> d = {
      {"sl_msgs/msg/CommandReply", &sl_msgs_msg_dds__CommandReply__desc},
      {"sl_msgs/msg/CommandRequest", &sl_msgs_msg_dds__CommandRequest__desc},
      {"sl_msgs/msg/ImageSet", &sl_msgs_msg_dds__ImageSet__desc},
      {"sl_msgs/msg/PointsReader", &sl_msgs_msg_dds__PointsReader__desc},
      {"sl_msgs/msg/ProjectorMaps", &sl_msgs_msg_dds__ProjectorMaps__desc},
      {"sl_msgs/msg/Status", &sl_msgs_msg_dds__Status__desc},
      {"sl_msgs/srv/GetConfig_Request", &sl_msgs_srv_dds__GetConfig_Request__desc},
      {"sl_msgs/srv/GetConfig_Response", &sl_msgs_srv_dds__GetConfig_Response__desc},
      {"sl_msgs/srv/ListPatterns_Request", &sl_msgs_srv_dds__ListPatterns_Request__desc},
      {"sl_msgs/srv/ListPatterns_Response", &sl_msgs_srv_dds__ListPatterns_Response__desc},
      {"sl_msgs/srv/SetPattern_Request", &sl_msgs_srv_dds__SetPattern_Request__desc},
      {"sl_msgs/srv/SetPattern_Response", &sl_msgs_srv_dds__SetPattern_Response__desc},
      {"sl_msgs/srv/Start_Request", &sl_msgs_srv_dds__Start_Request__desc},
      {"sl_msgs/srv/Start_Response", &sl_msgs_srv_dds__Start_Response__desc},
      {"std_srvs/srv/Trigger_Request", &std_srvs_srv_dds__Trigger_Request__desc},
      {"std_srvs/srv/Trigger_Response", &std_srvs_srv_dds__Trigger_Response__desc},
  };
  return d;
}

std::vector<unsigned char> fromHex(const std::string& hex) {
  std::vector<unsigned char> bytes;
  for (std::size_t i = 0; i + 1 < hex.size(); i += 2)
    bytes.push_back(static_cast<unsigned char>(std::stoi(hex.substr(i, 2), nullptr, 16)));
  return bytes;
}

std::string toHex(const std::vector<unsigned char>& bytes) {
  static const char* digits = "0123456789abcdef";
  std::string hex;
  for (unsigned char b : bytes) {
    hex += digits[b >> 4];
    hex += digits[b & 15];
  }
  return hex;
}

// The next sample of `reader`, serialized; null after 5 s without one.
ddsi_serdata* takeSerialized(dds_entity_t reader) {
  for (int i = 0; i < 500; ++i) {
    ddsi_serdata* d = nullptr;
    dds_sample_info_t info;
    if (dds_takecdr(reader, &d, 1, &info, DDS_ANY_STATE) == 1) {
      if (info.valid_data) return d;
      ddsi_serdata_unref(d);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return nullptr;
}

std::vector<unsigned char> bytesOf(ddsi_serdata* d) {
  std::vector<unsigned char> bytes(ddsi_serdata_size(d));
  ddsi_serdata_to_ser(d, 0, bytes.size(), bytes.data());
  return bytes;
}

// One type's topic, writer and reader.
class Endpoint {
 public:
  Endpoint(dds_entity_t participant, const dds_topic_descriptor_t* desc, const std::string& name)
      : desc_(desc) {
    const std::string topic_name =
        "rt/sl_msgs_wire_" + std::to_string(getpid()) + "_" + std::to_string(++count_);
    topic_ = dds_create_topic(participant, desc, topic_name.c_str(), nullptr, nullptr);
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(5));
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
    writer_ = dds_create_writer(participant, topic_, qos, nullptr);
    reader_ = dds_create_reader(participant, topic_, qos, nullptr);
    dds_delete_qos(qos);
    if (topic_ < 0 || writer_ < 0 || reader_ < 0) throw std::runtime_error("cannot create endpoints of " + name);
    // The type Cyclone serializes with: from a sample of the writer's.
    void* zero = dds_alloc(desc->m_size);
    const bool wrote = dds_write(writer_, zero) == DDS_RETCODE_OK;
    dds_sample_free(zero, desc, DDS_FREE_ALL);
    ddsi_serdata* first = wrote ? takeSerialized(reader_) : nullptr;
    if (first == nullptr) throw std::runtime_error("no sample of " + name + " came back");
    type_ = first->type;
    ddsi_serdata_unref(first);
  }

  // `bytes` taken as the reader takes them, written by the writer, and as
  // the writer put them on the wire. Throws when Cyclone refuses them.
  std::vector<unsigned char> roundTrip(const std::vector<unsigned char>& bytes) {
    ddsrt_iovec_t iov;
    iov.iov_base = const_cast<unsigned char*>(bytes.data());
    iov.iov_len = static_cast<decltype(iov.iov_len)>(bytes.size());
    ddsi_serdata* in = ddsi_serdata_from_ser_iov(type_, SDK_DATA, 1, &iov, bytes.size());
    if (in == nullptr) throw std::runtime_error("Cyclone refuses to deserialize the sample");
    void* sample = dds_alloc(desc_->m_size);
    const bool ok = ddsi_serdata_to_sample(in, sample, nullptr, nullptr);
    ddsi_serdata_unref(in);
    if (!ok) {
      dds_sample_free(sample, desc_, DDS_FREE_ALL);
      throw std::runtime_error("Cyclone cannot convert the sample");
    }
    const bool wrote = dds_write(writer_, sample) == DDS_RETCODE_OK;
    dds_sample_free(sample, desc_, DDS_FREE_ALL);
    ddsi_serdata* out = wrote ? takeSerialized(reader_) : nullptr;
    if (out == nullptr) throw std::runtime_error("the written sample did not come back");
    auto result = bytesOf(out);
    ddsi_serdata_unref(out);
    return result;
  }

 private:
  static inline int count_ = 0;
  const dds_topic_descriptor_t* desc_;
  dds_entity_t topic_ = -1, writer_ = -1, reader_ = -1;
  const ddsi_sertype* type_ = nullptr;
};

}  // namespace

int main() {
  const dds_entity_t participant = dds_create_participant(DDS_DOMAIN_DEFAULT, nullptr, nullptr);
  if (participant < 0) {
    std::fprintf(stderr, "sl_msgs_cyclone_roundtrip: no participant: %s\n", dds_strretcode(participant));
    return 1;
  }
  std::map<std::string, std::unique_ptr<Endpoint>> endpoints;
  int status = 0;
  for (std::string line; std::getline(std::cin, line);) {
    std::istringstream words(line);
    std::string type, hex;
    words >> type >> hex;
    if (type.empty()) continue;
    try {
      const auto desc = descriptors().find(type);
      if (desc == descriptors().end()) throw std::runtime_error("no DDS type for it in sl_idl");
      auto& endpoint = endpoints[type];
      if (!endpoint) endpoint = std::make_unique<Endpoint>(participant, desc->second, type);
      const std::string out = toHex(endpoint->roundTrip(fromHex(hex)));
      std::cout << type << " " << out << " " << desc->second->m_typename << "\n";
    } catch (const std::exception& e) {
      std::cout << type << " ERROR " << e.what() << "\n";
      status = 1;
    }
  }
  std::cout.flush();
  endpoints.clear();
  dds_delete(participant);
  return status;
}
