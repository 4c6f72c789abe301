// The DDS bridge in the test's own process (linked into test_e2e): bridges
// and scan engines on the small simulated rig of fuzz/data/request_daemon.yaml,
// each under its own namespace, and clients in the same process.
#include "support/time_scale.h"
#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "daemon_process.h"
#include "sl/client/client.h"
#include "sl/daemon/config.h"
#include "sl/dds/dds.h"
#include "sl/daemon/dds_bridge.h"
#include "sl/daemon/devices.h"
#include "sl/daemon/scan_engine.h"
#include "sl_msgs/msg/CommandRequest.h"

using namespace std::chrono_literals;

namespace {

// sl_sensord's composition (daemon/src/main.cpp) without the process: the
// bridge serves once serve() was called.
struct InProcessDaemon {
  sl::daemon::DaemonConfig config;
  std::shared_ptr<void> owner;
  std::unique_ptr<sl::daemon::DdsBridge> bridge;
  std::unique_ptr<sl::daemon::ScanEngine> engine;
  std::thread server;

  explicit InProcessDaemon(const std::string& ns) {
    YAML::Node root = YAML::LoadFile(sl::test::sourcePath("fuzz/data/request_daemon.yaml"));
    root["dds"]["namespace"] = ns;
    config = sl::daemon::loadConfig(sl::test::writeConfigFile(root, ns));
    sl::daemon::EngineDevices devices = sl::daemon::openDevices(config, owner);
    bridge = std::make_unique<sl::daemon::DdsBridge>(config.dds, devices.cameras.front()->id(),
                                                     config.calibration, config.extra_calibrations);
    engine = std::make_unique<sl::daemon::ScanEngine>(
        config, std::move(devices), [this](const sl::daemon::ScanResult& r) { bridge->publish(r); },
        bridge->resultContents());
  }
  void serve() {
    server = std::thread([this] { bridge->serve(*engine); });
  }
  ~InProcessDaemon() {
    bridge->stop();
    if (server.joinable()) server.join();
    engine.reset();  // before the bridge it publishes to
  }
};

std::unique_ptr<sl::client::SensorClient> connectTo(const std::string& ns) {
  sl::client::ClientOptions options;
  options.ns = ns;
  options.subscribe_points = false;
  auto client = std::make_unique<sl::client::SensorClient>(options);
  REQUIRE(client->waitForDaemon(sl::test::scaledBound(20s)));
  return client;
}

}  // namespace

// Cyclone has one log sink per process; each bridge counts the samples of
// its own request topic that fail to deserialize, however many bridges the
// process holds (it was the last one created that counted them all).
TEST_CASE("several bridges in one process each count their own malformed requests") {
  sl::test::useLoopbackDds();
  const std::string ns_a = sl::test::uniqueNamespace("malformed_a");
  const std::string ns_b = ns_a + "_b";
  InProcessDaemon a(ns_a);
  InProcessDaemon b(ns_b);
  a.serve();
  b.serve();
  auto write = [](const std::string& ns, int count) {
    const std::string command = std::string(SL_BINARY_DIR) + "/tests/malformed_writer " + ns +
                                " " + std::to_string(count);
    REQUIRE(std::system(command.c_str()) == 0);
  };
  write(ns_a, 3);
  write(ns_b, 5);
  {
    // A third bridge, created last and gone again, takes nothing with it.
    InProcessDaemon c(ns_a + "_c");
    write(ns_a + "_c", 2);
  }
  write(ns_a, 1);
  const auto client_a = connectTo(ns_a);
  const auto client_b = connectTo(ns_b);
  const auto sa = sl::test::statusWhen(
      *client_a, [](const auto& s) { return s.requests_malformed >= 4; }, sl::test::scaledBound(5s));
  const auto sb = sl::test::statusWhen(
      *client_b, [](const auto& s) { return s.requests_malformed >= 5; }, sl::test::scaledBound(5s));
  REQUIRE(sa);
  REQUIRE(sb);
  CHECK(sa->requests_malformed == 4);
  CHECK(sb->requests_malformed == 5);
  // Both still answer.
  CHECK(client_a->request(sl::client::Command::kListPatterns, "", 0, sl::test::scaledBound(5s)));
  CHECK(client_b->request(sl::client::Command::kListPatterns, "", 0, sl::test::scaledBound(5s)));
}

// The request reader keeps at most 256 unread requests; what it refuses
// beyond them is counted (requests_rejected), not lost without a trace.
TEST_CASE("requests refused by the full request reader are counted") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("rejected");
  InProcessDaemon daemon(ns);  // not serving yet: nothing takes the requests
  sl::dds::Participant participant(0);
  sl::dds::Topic<sl_msgs_msg_dds__CommandRequest_> topic(participant, "rq/" + ns + "/commandRequest",
                                                   sl_msgs_msg_dds__CommandRequest__desc);
  // Each write waits at most 20 ms for a full reader (in one process, Cyclone
  // delivers to the reader synchronously and retries a refused sample until
  // then), then gives the request up.
  sl::dds::Writer<sl_msgs_msg_dds__CommandRequest_> writer(
      participant, topic, sl::dds::Qos().reliable(DDS_MSECS(20)).keepAll().xcdr1());
  REQUIRE(writer.waitForReaders(1, DDS_SECS(10)));
  constexpr int kRequests = 300;
  int written = 0;
  for (int i = 0; i < kRequests; ++i) {
    std::string client_id = "flood" + std::to_string(i), empty;
    sl_msgs_msg_dds__CommandRequest_ request{};
    request.client_id = client_id.data();
    request.request_id = 1;
    request.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS;
    request.pattern = request.recording = empty.data();
    if (writer.write(request)) ++written;
  }
  CHECK(written == 256);  // the reader's limit; the rest timed out at the writer
  daemon.serve();
  const auto client = connectTo(ns);
  const auto s = sl::test::statusWhen(
      *client, [](const auto& s) { return s.requests_received >= 256; }, sl::test::scaledBound(10s));
  REQUIRE(s);
  CHECK(s->requests_received == 256);
  CHECK(s->requests_rejected >= kRequests - 256);  // each refused sample at least once
  CHECK(s->requests_answered + s->requests_rate_limited + s->replies_timed_out ==
        s->requests_received);
}

// The flood probe of the hardening issue (one unthrottled writer of 20k
// LIST_PATTERNS got 17 % answered, and honest clients' STOPs timed out):
// a client that writes as fast as the reliable protocol lets it is held back
// at its own writer and rate-limited; another client is answered meanwhile,
// and every request the daemon took is answered or counted.
TEST_CASE("a flooding client neither starves another client nor loses requests uncounted") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("flood");
  InProcessDaemon daemon(ns);
  daemon.serve();
  const auto honest = connectTo(ns);

  sl::dds::Participant participant(0);
  sl::dds::Topic<sl_msgs_msg_dds__CommandRequest_> topic(participant, "rq/" + ns + "/commandRequest",
                                                   sl_msgs_msg_dds__CommandRequest__desc);
  sl::dds::Writer<sl_msgs_msg_dds__CommandRequest_> writer(
      participant, topic, sl::dds::Qos().reliable(DDS_MSECS(500)).keepAll().xcdr1());
  REQUIRE(writer.waitForReaders(1, DDS_SECS(10) * sl::test::kTimeScale));
  // The flood: at least the probe's 20k requests, and on until the honest
  // client is done, so that every honest request meets it however fast the
  // daemon drains it (bounded by kFloodMax).
  constexpr int kFloodMin = 20000, kFloodMax = 2'000'000, kHonest = 5;
  std::atomic<int> written{0};
  std::atomic<bool> honest_done{false}, flooding{true};
  std::thread flood([&] {
    std::string client_id = "flooder", empty;
    for (int i = 0; i < kFloodMax && (i < kFloodMin || !honest_done); ++i) {
      sl_msgs_msg_dds__CommandRequest_ request{};
      request.client_id = client_id.data();
      request.request_id = static_cast<std::uint32_t>(i + 1);  // all distinct: none is a repeat
      request.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS;
      request.pattern = request.recording = empty.data();
      if (writer.write(request)) ++written;
    }
    flooding = false;
  });
  // The honest client's requests during the flood: each answered within
  // slctl's default timeout (5 s, retries included in request()).
  int honest_sent = 0, honest_answered = 0;
  for (; honest_sent < kHonest; ++honest_sent) {
    const auto reply = honest->request(sl::client::Command::kStop, "", 0, sl::test::scaledBound(5s));
    if (reply) ++honest_answered;  // NOT_RUNNING: nothing was scanning, but answered
    std::this_thread::sleep_for(50ms);
  }
  const bool flood_outlasted = flooding;  // it ran during every honest request
  honest_done = true;
  flood.join();
  INFO("flooder wrote " << written << "; the honest client sent " << honest_sent);
  CHECK(flood_outlasted);
  CHECK(honest_answered == honest_sent);

  const auto s = sl::test::statusWhen(
      *honest,
      [&](const auto& s) {
        return s.requests_answered + s.requests_rate_limited + s.replies_timed_out ==
                   s.requests_received &&
               s.requests_received >= std::uint64_t(written + honest_sent);
      },
      sl::test::scaledBound(20s));
  REQUIRE(s);
  INFO("received " << s->requests_received << ", answered " << s->requests_answered
                   << ", rate-limited " << s->requests_rate_limited << ", timed out "
                   << s->replies_timed_out << ", rejected " << s->requests_rejected);
  // Every sample the flooder's writer delivered was taken (reliable, and the
  // reader refuses only while full, which holds the writer back): all
  // accounted for, none lost between the writer and the counters.
  CHECK(s->requests_received >= std::uint64_t(written + honest_sent));
  CHECK(s->requests_answered + s->requests_rate_limited + s->replies_timed_out ==
        s->requests_received);
  // 20 requests/s per client after a burst of 40: most of the flood is
  // rate-limited, not answered.
  CHECK(s->requests_rate_limited > 0);
  CHECK(s->requests_rate_limited >= std::uint64_t(written) / 2);
}
