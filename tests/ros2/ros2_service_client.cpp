// A ROS 2 service client in the framing of rmw_cyclonedds, for
// tools/sl_view/test/ros2_services_check.mjs: per service of the daemon, a
// request writer and a response reader on rq/<ns>/<name>Request and
// rr/<ns>/<name>Reply, both with USER_DATA "clientid=<id>;" as rmw_cyclonedds
// gives a client's endpoints; a request is the 4-byte encapsulation, the
// request header (guid = the request writer's instance handle, seq) and the
// message. The messages come from the caller already serialized (Foxglove's
// serializer) and the responses go back as taken (Foxglove's deserializer
// reads them): this program only frames and moves bytes.
//
// usage: ros2_service_client NAMESPACE; then lines on stdin:
//   call SERVICE SEQ HEX    send a request (HEX: encapsulation + message)
//   wait MS                 print "reply SERVICE HEX" for every response taken
//                           within MS (all of them: a client filters on its guid)
//   status                  print "status HEX": the daemon's latest status
// After start-up it prints "guid SERVICE N" per service and "ready".
#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>
#include <unistd.h>

#include "sl_msgs/msg/Status.h"
#include "sl_msgs/srv/GetConfig.h"
#include "sl_msgs/srv/ListPatterns.h"
#include "sl_msgs/srv/SetPattern.h"
#include "sl_msgs/srv/Start.h"
#include "std_srvs/srv/Trigger.h"

namespace {

struct ServiceTypes {
  const dds_topic_descriptor_t* request;
  const dds_topic_descriptor_t* response;
};

const std::map<std::string, ServiceTypes>& services() {
  static const std::map<std::string, ServiceTypes> s = {
      {"start", {&sl_msgs_srv_dds__Start_Request__desc, &sl_msgs_srv_dds__Start_Response__desc}},
      {"stop", {&std_srvs_srv_dds__Trigger_Request__desc, &std_srvs_srv_dds__Trigger_Response__desc}},
      {"set_pattern",
       {&sl_msgs_srv_dds__SetPattern_Request__desc, &sl_msgs_srv_dds__SetPattern_Response__desc}},
      {"list_patterns",
       {&sl_msgs_srv_dds__ListPatterns_Request__desc, &sl_msgs_srv_dds__ListPatterns_Response__desc}},
      {"get_config",
       {&sl_msgs_srv_dds__GetConfig_Request__desc, &sl_msgs_srv_dds__GetConfig_Response__desc}},
  };
  return s;
}

std::vector<unsigned char> fromHex(const std::string& hex) {
  std::vector<unsigned char> bytes;
  for (std::size_t i = 0; i + 1 < hex.size(); i += 2)
    bytes.push_back(static_cast<unsigned char>(std::stoi(hex.substr(i, 2), nullptr, 16)));
  return bytes;
}

std::string toHex(const unsigned char* p, std::size_t n) {
  static const char* digits = "0123456789abcdef";
  std::string hex;
  for (std::size_t i = 0; i < n; ++i) {
    hex += digits[p[i] >> 4];
    hex += digits[p[i] & 15];
  }
  return hex;
}

std::string serialized(ddsi_serdata* d) {
  std::vector<unsigned char> bytes(ddsi_serdata_size(d));
  ddsi_serdata_to_ser(d, 0, bytes.size(), bytes.data());
  return toHex(bytes.data(), bytes.size());
}

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "ros2_service_client: %s\n", what.c_str());
  std::exit(1);
}

dds_entity_t check(dds_entity_t e, const std::string& what) {
  if (e < 0) die(what + ": " + dds_strretcode(e));
  return e;
}

struct Client {
  const dds_topic_descriptor_t* request_type = nullptr;
  dds_entity_t writer = 0, reader = 0;
  const ddsi_sertype* sertype = nullptr;  // the request type's, for samples from bytes
  std::uint64_t guid = 0;
};

// The sertype Cyclone serializes `desc` with, from a sample written to a
// private probe topic (never to the daemon's).
const ddsi_sertype* sertypeOf(dds_entity_t participant, const dds_topic_descriptor_t* desc,
                              const std::string& name) {
  const std::string topic_name = "sl_service_client_probe_" + std::to_string(getpid()) + "_" + name;
  const dds_entity_t topic = check(dds_create_topic(participant, desc, topic_name.c_str(), nullptr, nullptr),
                                   "probe topic");
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  const dds_entity_t writer = check(dds_create_writer(participant, topic, qos, nullptr), "probe writer");
  const dds_entity_t reader = check(dds_create_reader(participant, topic, qos, nullptr), "probe reader");
  dds_delete_qos(qos);
  void* zero = dds_alloc(desc->m_size);
  dds_write(writer, zero);
  dds_sample_free(zero, desc, DDS_FREE_ALL);
  for (int i = 0; i < 500; ++i) {
    ddsi_serdata* d = nullptr;
    dds_sample_info_t info;
    if (dds_takecdr(reader, &d, 1, &info, DDS_ANY_STATE) == 1) {
      const ddsi_sertype* type = d->type;
      ddsi_serdata_unref(d);  // the topic keeps the sertype
      return type;
    }
    dds_sleepfor(DDS_MSECS(10));
  }
  die("no probe sample for " + name);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) die("usage: ros2_service_client NAMESPACE");
  const std::string ns = argv[1];
  const dds_entity_t participant = check(dds_create_participant(DDS_DOMAIN_DEFAULT, nullptr, nullptr),
                                         "participant");
  std::mt19937_64 random(std::random_device{}());
  std::map<std::string, Client> clients;
  for (const auto& [name, types] : services()) {
    Client& c = clients[name];
    c.request_type = types.request;
    const std::string request_topic = "rq/" + ns + "/" + name + "Request";
    const std::string reply_topic = "rr/" + ns + "/" + name + "Reply";
    const dds_entity_t rq = check(dds_create_topic(participant, types.request, request_topic.c_str(), nullptr, nullptr),
                                  request_topic);
    const dds_entity_t rr = check(dds_create_topic(participant, types.response, reply_topic.c_str(), nullptr, nullptr),
                                  reply_topic);
    // rmw's default service QoS (reliable, volatile, keep last 10); both
    // endpoints of this client carry its id.
    const std::string user_data = "clientid=" + std::to_string(random()) + ";";
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
    dds_qset_userdata(qos, user_data.data(), user_data.size());
    c.writer = check(dds_create_writer(participant, rq, qos, nullptr), "request writer");
    c.reader = check(dds_create_reader(participant, rr, qos, nullptr), "response reader");
    dds_delete_qos(qos);
    dds_instance_handle_t handle = 0;
    dds_get_instance_handle(c.writer, &handle);
    c.guid = handle;
    c.sertype = sertypeOf(participant, types.request, name);
  }
  // The daemon's status, as a late joiner gets it.
  const std::string status_name = "rt/" + ns + "/status";
  const dds_entity_t status_topic =
      check(dds_create_topic(participant, &sl_msgs_msg_dds__Status__desc, status_name.c_str(), nullptr, nullptr),
            status_name);
  dds_qos_t* status_qos = dds_create_qos();
  dds_qset_reliability(status_qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(status_qos, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(status_qos, DDS_HISTORY_KEEP_LAST, 1);
  const dds_entity_t status_reader = check(dds_create_reader(participant, status_topic, status_qos, nullptr),
                                           "status reader");
  dds_delete_qos(status_qos);

  // Ready when every request writer and response reader has matched the daemon.
  for (int i = 0; i < 1000; ++i) {
    bool all = true;
    for (const auto& [name, c] : clients) {
      dds_publication_matched_status_t pm;
      dds_subscription_matched_status_t sm;
      dds_get_publication_matched_status(c.writer, &pm);
      dds_get_subscription_matched_status(c.reader, &sm);
      all = all && pm.current_count > 0 && sm.current_count > 0;
    }
    if (all) break;
    if (i == 999) die("the daemon's services did not match within 10 s");
    dds_sleepfor(DDS_MSECS(10));
  }
  for (const auto& [name, c] : clients) std::cout << "guid " << name << " " << c.guid << "\n";
  std::cout << "ready" << std::endl;

  for (std::string line; std::getline(std::cin, line);) {
    std::istringstream words(line);
    std::string verb;
    words >> verb;
    if (verb == "call") {
      std::string name, hex;
      std::int64_t seq = 0;
      words >> name >> seq >> hex;
      const auto it = clients.find(name);
      if (it == clients.end()) die("no service " + name);
      Client& c = it->second;
      std::vector<unsigned char> message = fromHex(hex);
      if (message.size() < 4) die("call " + name + ": no encapsulation");
      // encapsulation | guid | seq | message
      std::vector<unsigned char> bytes(message.begin(), message.begin() + 4);
      bytes.resize(20);
      std::memcpy(bytes.data() + 4, &c.guid, 8);
      std::memcpy(bytes.data() + 12, &seq, 8);
      bytes.insert(bytes.end(), message.begin() + 4, message.end());
      ddsrt_iovec_t iov;
      iov.iov_base = bytes.data();
      iov.iov_len = static_cast<decltype(iov.iov_len)>(bytes.size());
      ddsi_serdata* d = ddsi_serdata_from_ser_iov(c.sertype, SDK_DATA, 1, &iov, bytes.size());
      if (d == nullptr) die("call " + name + ": Cyclone refuses the request bytes");
      void* sample = dds_alloc(c.request_type->m_size);
      const bool ok = ddsi_serdata_to_sample(d, sample, nullptr, nullptr);
      ddsi_serdata_unref(d);
      if (!ok || dds_write(c.writer, sample) != DDS_RETCODE_OK) die("call " + name + ": not written");
      dds_sample_free(sample, c.request_type, DDS_FREE_ALL);
    } else if (verb == "wait") {
      int ms = 0;
      words >> ms;
      const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
      while (std::chrono::steady_clock::now() < end) {
        for (const auto& [name, c] : clients) {
          ddsi_serdata* d = nullptr;
          dds_sample_info_t info;
          while (dds_takecdr(c.reader, &d, 1, &info, DDS_ANY_STATE) == 1) {
            if (info.valid_data) std::cout << "reply " << name << " " << serialized(d) << "\n";
            ddsi_serdata_unref(d);
          }
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
      std::cout << "waited" << std::endl;
    } else if (verb == "status") {
      ddsi_serdata* d = nullptr;
      dds_sample_info_t info;
      std::string hex;
      for (int i = 0; i < 500 && hex.empty(); ++i) {
        if (dds_readcdr(status_reader, &d, 1, &info, DDS_ANY_STATE) == 1) {
          if (info.valid_data) hex = serialized(d);
          ddsi_serdata_unref(d);
        } else {
          dds_sleepfor(DDS_MSECS(10));
        }
      }
      std::cout << "status " << (hex.empty() ? "none" : hex) << std::endl;
    } else if (verb == "quit") {
      break;
    }
  }
  dds_delete(participant);
  return 0;
}
