// A listener of the daemon's ROS 2 graph topics for
// tools/sl_view/test/ros2_graph_check.mjs: it subscribes to rt/tf_static,
// rt/diagnostics and ros_discovery_info with the QoS a ROS 2 subscriber uses
// (tf2_ros's static listener and rmw's graph reader: reliable,
// transient-local; diagnostics: reliable, volatile) and prints every sample
// as the bytes it came in (encapsulation + CDR). It never deserializes them:
// the caller decodes them with Foxglove's ROS 2 deserializer and the
// standard definitions. The types given to Cyclone only name the topics'
// types (ROS 2's DDS type names); the bytes are taken with dds_takecdr.
//
// It also prints what DDS discovery says of every remote writer (the
// builtin DCPSPublication topic), so the caller can check the writers' QoS
// and that ros_discovery_info lists the points writer's GUID.
//
// usage: ros2_graph_listener SECONDS
// prints, as they come, until SECONDS have passed:
//   sample TOPIC RECEPTION_NS HEX
//   writer TOPIC TYPE GUID PARTICIPANT_GUID RELIABILITY DURABILITY HISTORY DEPTH
// with RELIABILITY reliable|best_effort, DURABILITY volatile|transient_local|...,
// HISTORY keep_last|keep_all, GUID as 32 hex digits.
#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <set>
#include <string>
#include <vector>

#include "diagnostic_msgs/msg/DiagnosticArray.h"
#include "rmw_dds_common/msg/ParticipantEntitiesInfo.h"
#include "tf2_msgs/msg/TFMessage.h"

namespace {

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "ros2_graph_listener: %s\n", what.c_str());
  std::exit(1);
}

dds_entity_t check(dds_entity_t e, const std::string& what) {
  if (e < 0) die(what + ": " + dds_strretcode(e));
  return e;
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

std::int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct Subscription {
  std::string topic;
  dds_entity_t reader;
};

Subscription subscribe(dds_entity_t participant, const dds_topic_descriptor_t* type, const std::string& topic,
                       bool transient_local) {
  const dds_entity_t t = check(dds_create_topic(participant, type, topic.c_str(), nullptr, nullptr), topic);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  if (transient_local) {
    dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  } else {
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
  }
  const dds_entity_t reader = check(dds_create_reader(participant, t, qos, nullptr), topic + " reader");
  dds_delete_qos(qos);
  return {topic, reader};
}

const char* reliabilityName(dds_reliability_kind_t k) {
  return k == DDS_RELIABILITY_RELIABLE ? "reliable" : "best_effort";
}

const char* durabilityName(dds_durability_kind_t k) {
  switch (k) {
    case DDS_DURABILITY_VOLATILE: return "volatile";
    case DDS_DURABILITY_TRANSIENT_LOCAL: return "transient_local";
    case DDS_DURABILITY_TRANSIENT: return "transient";
    case DDS_DURABILITY_PERSISTENT: return "persistent";
  }
  return "unknown";
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) die("usage: ros2_graph_listener SECONDS DOMAIN");
  const double seconds = std::atof(argv[1]);
  if (!(seconds > 0 && seconds < 600)) die("SECONDS must be in (0, 600)");
  // /tf_static, /diagnostics and ros_discovery_info are not namespaced: the
  // test's daemon gets a domain of its own, so no other daemon is heard.
  const int domain = std::atoi(argv[2]);
  if (domain < 0 || domain > 232) die("DOMAIN must be in 0..232");
  const dds_entity_t participant =
      check(dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr), "participant");
  std::vector<Subscription> subs = {
      subscribe(participant, &tf2_msgs_msg_dds__TFMessage__desc, "rt/tf_static", true),
      subscribe(participant, &diagnostic_msgs_msg_dds__DiagnosticArray__desc, "rt/diagnostics", false),
      subscribe(participant, &rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc, "ros_discovery_info", true),
  };
  const dds_entity_t publications =
      check(dds_create_reader(participant, DDS_BUILTIN_TOPIC_DCPSPUBLICATION, nullptr, nullptr),
            "DCPSPublication reader");
  dds_guid_t own{};
  dds_get_guid(participant, &own);

  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  std::set<std::string> writers_seen;
  while (std::chrono::steady_clock::now() < end) {
    for (const Subscription& s : subs) {
      for (;;) {
        ddsi_serdata* d = nullptr;
        dds_sample_info_t info;
        if (dds_takecdr(s.reader, &d, 1, &info, DDS_ANY_STATE) != 1) break;
        if (info.valid_data) {
          std::vector<unsigned char> bytes(ddsi_serdata_size(d));
          ddsi_serdata_to_ser(d, 0, bytes.size(), bytes.data());
          std::cout << "sample " << s.topic << " " << nowNs() << " " << toHex(bytes.data(), bytes.size())
                    << std::endl;
        }
        ddsi_serdata_unref(d);
      }
    }
    void* raw[16] = {};
    dds_sample_info_t infos[16];
    const dds_return_t n = dds_take(publications, raw, infos, 16, 16);
    for (dds_return_t i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* p = static_cast<const dds_builtintopic_endpoint_t*>(raw[i]);
      if (std::equal(std::begin(own.v), std::end(own.v), p->participant_key.v)) continue;
      const std::string guid = toHex(p->key.v, sizeof p->key.v);
      if (!writers_seen.insert(guid).second) continue;
      dds_reliability_kind_t reliability = DDS_RELIABILITY_BEST_EFFORT;
      dds_durability_kind_t durability = DDS_DURABILITY_VOLATILE;
      dds_history_kind_t history = DDS_HISTORY_KEEP_LAST;
      std::int32_t depth = 1;
      dds_qget_reliability(p->qos, &reliability, nullptr);
      dds_qget_durability(p->qos, &durability);
      dds_qget_history(p->qos, &history, &depth);
      std::cout << "writer " << p->topic_name << " " << p->type_name << " " << guid << " "
                << toHex(p->participant_key.v, sizeof p->participant_key.v) << " " << reliabilityName(reliability)
                << " " << durabilityName(durability) << " "
                << (history == DDS_HISTORY_KEEP_ALL ? "keep_all" : "keep_last") << " " << depth << std::endl;
    }
    if (n > 0) dds_return_loan(publications, raw, n);
    dds_sleepfor(DDS_MSECS(20));
  }
  dds_delete(participant);
  return 0;
}
