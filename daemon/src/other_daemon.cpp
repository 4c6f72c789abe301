#include "other_daemon.h"

#include <cstring>
#include <thread>

#include "sl/dds/dds.h"
#include "sl/daemon/dds_bridge.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::dds::TopicNames;

// Through the built-in DCPSSubscription topic (every reader discovery has
// seen, with its topic name): needs no permission under DDS Security, where
// the sensor identity may not write requests itself.
bool otherDaemonServes(const DdsConfig& config, std::chrono::milliseconds window) {
  const std::string request_topic = TopicNames::forNamespace(config.ns).request;
  dds::Participant participant(config.domain_id);
  const dds_entity_t reader =
      dds_create_reader(participant.handle(), DDS_BUILTIN_TOPIC_DCPSSUBSCRIPTION, nullptr, nullptr);
  if (reader < 0) throw dds::Error("dds_create_reader(DCPSSubscription)", reader);
  const auto deadline = std::chrono::steady_clock::now() + window;
  bool found = false;
  while (!found && std::chrono::steady_clock::now() < deadline) {
    void* samples[16] = {};
    dds_sample_info_t infos[16];
    const dds_return_t n = dds_take(reader, samples, infos, 16, 16);
    if (n < 0) throw dds::Error("dds_take(DCPSSubscription)", n);
    for (dds_return_t i = 0; i < n; ++i) {
      const auto* endpoint = static_cast<const dds_builtintopic_endpoint_t*>(samples[i]);
      if (infos[i].valid_data && infos[i].instance_state == DDS_IST_ALIVE && endpoint->topic_name &&
          request_topic == endpoint->topic_name)
        found = true;
    }
    if (n > 0) dds_return_loan(reader, samples, n);
    if (!found) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return found;
}

}  // namespace sl::daemon
