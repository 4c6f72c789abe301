#include "mcap_record.h"

#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <optional>
#include <thread>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/cdr.h"
#include "common/cli.h"
#include "common/mcap_writer.h"
#include "common/ros2_schemas.h"
#include "raw_topics.h"
#include "sl/daemon/client.h"

namespace sl::view {

int recordMain(int argc, char** argv, const std::atomic<bool>& stop) {
  if (argc < 2 || argv[1][0] == '-')
    throw std::invalid_argument("record needs the output file (sl_view record FILE.mcap)");
  const std::string path = argv[1];
  RawTopicsOptions topics;
  topics.depth = 8;  // room for a burst while a chunk is compressed
  tools::McapWriterOptions mcap;
  long count = 0, scan = -1;  // scan: -1 none, 0 continuous
  double seconds = 0;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    const auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    const auto integer = [&](int lo, int hi) {
      const std::string v = value();
      const auto n = tools::toInt(v);
      if (!n || *n < lo || *n > hi)
        throw std::invalid_argument(a + " " + v + ": expected an integer in [" +
                                    std::to_string(lo) + ", " + std::to_string(hi) + "]");
      return *n;
    };
    if (a == "--topics") {
      std::stringstream list(value());
      for (std::string t; std::getline(list, t, ',');)
        if (!t.empty()) topics.only.push_back(t);
    } else if (a == "--count") count = integer(1, 1000000);
    else if (a == "--scan") scan = integer(0, 1000000);
    else if (a == "--seconds") {
      const std::string v = value();
      const auto s = tools::toNumber(v);
      if (!s || *s <= 0) throw std::invalid_argument("--seconds " + v + ": expected a number > 0");
      seconds = *s;
    } else if (a == "--compression") {
      mcap.compression = value();
      if (mcap.compression == "none") mcap.compression.clear();
      if (mcap.compression != "" && mcap.compression != "zstd" && mcap.compression != "lz4")
        throw std::invalid_argument("--compression " + mcap.compression + ": zstd, lz4 or none");
    } else if (a == "--domain") topics.domain_id = integer(0, 232);
    else if (a == "--ns") topics.ns = value();
    else if (a == "--best-effort") topics.best_effort = true;
    else throw std::invalid_argument("record: unknown option '" + a + "'");
  }
  if (topics.only.empty()) {
    // Image sets and projector maps are big and off by default in the
    // daemon; name them with --topics to record them.
    for (const auto& t : daemonTopics(topics.ns))
      if (t.type_name != "sl_msgs/msg/ImageSet" && t.type_name != "sl_msgs/msg/ProjectorMaps")
        topics.only.push_back(t.ros_name);
  }

  RawTopics raw(topics);
  std::size_t status_topic = raw.topics().size(), points_topic = raw.topics().size();
  for (std::size_t i = 0; i < raw.topics().size(); ++i) {
    if (raw.topics()[i].type_name == "sl_msgs/msg/Status") status_topic = i;
    if (raw.topics()[i].type_name == "sensor_msgs/msg/PointCloud2") points_topic = i;
  }
  if (scan == 0 && count == 0)
    throw std::invalid_argument("--scan 0 (continuous) needs --count: the recording stops the scan");
  if ((count > 0 || scan >= 0) && points_topic == raw.topics().size())
    throw std::invalid_argument("--count/--scan count clouds: --topics must include /" +
                                topics.ns + "/points");

  tools::McapWriter writer(path, mcap);
  std::map<std::string, std::uint16_t> schema_ids;
  std::vector<std::uint16_t> channel_of(raw.topics().size());
  for (std::size_t i = 0; i < raw.topics().size(); ++i) {
    const auto& t = raw.topics()[i];
    auto it = schema_ids.find(t.type_name);
    if (it == schema_ids.end()) {
      const auto& schema = tools::ros2Schema(t.type_name);
      it = schema_ids.emplace(t.type_name, writer.addSchema(schema.name, "ros2msg", schema.definition)).first;
    }
    channel_of[i] = writer.addChannel(it->second, t.ros_name, "cdr");
  }

  const auto t0 = std::chrono::steady_clock::now();
  std::optional<daemon::SensorClient> client;
  if (scan >= 0) {
    daemon::ClientOptions co;
    co.domain_id = topics.domain_id;
    co.ns = topics.ns;
    co.subscribe_points = false;
    client.emplace(co);
    if (!client->waitForDaemon(std::chrono::seconds(10))) {
      std::cerr << "sl_view record: no daemon on domain " << topics.domain_id << " ns '"
                << topics.ns << "' within 10 s\n";
      return 3;
    }
    // Our readers must be matched before the first cloud is written.
    for (std::size_t i = 0; i < raw.topics().size(); ++i)
      if (i != status_topic)
        for (int k = 0; k < 200 && raw.matchedWriters(i) == 0; ++k)
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const auto reply = client->request(daemon::Command::kStart, "", static_cast<int>(scan),
                                      std::chrono::seconds(10));
    if (!reply) {
      std::cerr << "sl_view record: the daemon did not answer the scan request\n";
      return 3;
    }
    if (!reply->accepted) {
      std::cerr << "sl_view record: scan rejected: " << reply->reason << "\n";
      return 4;
    }
    if (count == 0) count = scan;
  }

  std::vector<std::uint32_t> sequence(raw.topics().size(), 0);
  long clouds = 0;
  std::uint64_t bytes = 0;
  // With --scan: the daemon going back to idle ends the recording too (a
  // scan it could not complete never comes); 0.5 s later, for the last
  // images.
  bool scanning_seen = false;
  std::optional<std::chrono::steady_clock::time_point> idle_since;
  while (!stop) {
    if (count > 0 && clouds >= count) break;
    if (idle_since && std::chrono::steady_clock::now() - *idle_since > std::chrono::milliseconds(500)) {
      std::cerr << "sl_view record: the daemon went idle after " << clouds << " of " << count
                << " clouds\n";
      break;
    }
    if (seconds > 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() >= seconds)
      break;
    raw.poll(DDS_MSECS(100), [&](std::shared_ptr<const RawSample> s) {
      if (count > 0 && clouds >= count) return;
      writer.write(channel_of[s->topic], ++sequence[s->topic], s->receive_ns, s->source_ns,
                   s->bytes());
      bytes += s->size();
      if (s->topic == points_topic) ++clouds;
      if (scan > 0 && s->topic == status_topic) {
        tools::CdrReader status(s->data(), s->size(), "status sample");
        status.i32();  // stamp
        status.u32();
        const std::uint32_t state = status.u32();  // sl_msgs State: 0 idle, 1 scanning
        if (state == 1 || state == 3) scanning_seen = true;
        if (state == 0 && scanning_seen && !idle_since) idle_since = std::chrono::steady_clock::now();
      }
    });
  }
  if (scan == 0) {
    const auto reply = client->request(daemon::Command::kStop, "", 0, std::chrono::seconds(10));
    if (!reply || !reply->accepted)
      std::cerr << "sl_view record: could not stop the scan: "
                << (reply ? reply->reason : std::string("no reply")) << "\n";
  }
  writer.close();
  std::printf("sl_view record: %llu messages (%ld clouds, %.1f MB of CDR) -> %s\n",
              static_cast<unsigned long long>(writer.messageCount()), clouds, bytes / 1e6,
              path.c_str());
  return 0;
}

}  // namespace sl::view
