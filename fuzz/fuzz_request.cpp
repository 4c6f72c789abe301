// The daemon's request handling end to end in one process: sl_sensord's
// DdsBridge and ScanEngine on a small simulated rig (data/request_daemon.yaml)
// serve rq/fuzz_request/commandRequest, and each input becomes one
// CommandRequest (arbitrary strings up to 300 KB, every command and enum
// value, counts, delays, start times, camera lists) written by a
// client participant. The target waits for the reply (or for the request to
// be counted as rate-limited) and checks it: same client and request id, a
// reason never longer than the bound. An accepted START is stopped again.
// Run in a private network namespace (scripts/fuzz.sh does).
#include <fuzzer/FuzzedDataProvider.h>

#include <chrono>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "msg_convert.h"
#include "sl/daemon/config.h"
#include "sl/dds/dds.h"
#include "sl/daemon/dds_bridge.h"
#include "sl/daemon/devices.h"
#include "sl/daemon/scan_engine.h"

namespace {

using namespace sl::daemon;
using ::sl::dds::TopicNames;
using namespace std::chrono_literals;

struct Daemon {
  DaemonConfig config;
  std::shared_ptr<void> owner;
  std::unique_ptr<DdsBridge> bridge;
  std::unique_ptr<ScanEngine> engine;
  std::thread server;
  // The client side.
  sl::dds::Participant participant{0};
  std::unique_ptr<sl::dds::Topic<msg::Request>> request_topic;
  std::unique_ptr<sl::dds::Topic<msg::Reply>> reply_topic;
  std::unique_ptr<sl::dds::Writer<msg::Request>> writer;
  std::unique_ptr<sl::dds::Reader<msg::Reply>> reader;
  std::uint64_t next_id = 1;

  Daemon() {
    config = loadConfig(std::string(SL_FUZZ_DIR) + "/data/request_daemon.yaml");
    EngineDevices devices = openDevices(config, owner);
    bridge = std::make_unique<DdsBridge>(config.dds, devices.cameras.front()->id(),
                                         config.calibration, config.extra_calibrations);
    engine = std::make_unique<ScanEngine>(config, std::move(devices),
                                          [this](const ScanResult& r) { bridge->publish(r); },
                                          bridge->resultContents());
    server = std::thread([this] { bridge->serve(*engine); });
    const TopicNames names = TopicNames::forNamespace(config.dds.ns);
    request_topic = std::make_unique<sl::dds::Topic<msg::Request>>(
        participant, names.request, sl_msgs_msg_dds__CommandRequest__desc);
    reply_topic = std::make_unique<sl::dds::Topic<msg::Reply>>(participant, names.reply,
                                                               sl_msgs_msg_dds__CommandReply__desc);
    writer = std::make_unique<sl::dds::Writer<msg::Request>>(
        participant, *request_topic, sl::dds::Qos().reliable().keepLast(16).xcdr1());
    reader = std::make_unique<sl::dds::Reader<msg::Reply>>(
        participant, *reply_topic, sl::dds::Qos().reliable().keepLast(64));
    if (!writer->waitForReaders(1, DDS_SECS(10)) || !reader->waitForWriters(1, DDS_SECS(10)))
      __builtin_trap();
  }

  // The reply to (client, id), or false after `timeout`.
  bool awaitReply(const std::string& client, std::uint64_t id, std::chrono::milliseconds timeout,
                  bool& accepted, std::size_t& reason_bytes) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      auto replies = reader->take(16);
      for (std::size_t i = 0; i < replies.size(); ++i) {
        if (!replies.isValid(i)) continue;
        const msg::Reply& r = replies[i];
        if (r.request_id != id || std::strcmp(r.client_id, client.c_str()) != 0) continue;
        accepted = r.accepted;
        reason_bytes = r.reason ? std::strlen(r.reason) : 0;
        return true;
      }
      if (replies.empty()) std::this_thread::sleep_for(200us);
    }
    return false;
  }
};

Daemon& daemon() {
  static Daemon* d = new Daemon;  // never destroyed: libFuzzer exits with _exit
  return *d;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  daemon();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Daemon& d = daemon();
  FuzzedDataProvider in(data, size);
  auto text = [&](std::size_t max) { return in.ConsumeRandomLengthString(max); };
  // Fresh client ids mostly, so the rate limit of one id is rarely what is tested.
  std::string client = in.ConsumeBool() ? "fuzz" + std::to_string(d.next_id) : text(400);
  std::string pattern = in.ConsumeBool() ? std::string(in.ConsumeIntegralInRange<std::size_t>(0, 300000), 'p')
                                         : text(64);
  std::string recording = text(64);
  std::vector<std::string> cameras;
  const int n_cameras = in.ConsumeIntegralInRange(0, 20);
  for (int i = 0; i < n_cameras; ++i) cameras.push_back(text(80));
  std::vector<char*> camera_ptrs;
  for (auto& c : cameras) camera_ptrs.push_back(c.data());

  msg::Request req{};
  req.client_id = client.data();
  req.request_id = d.next_id++;
  // Any uint8 (ros2/sl_msgs has constants, not IDL enums): the daemon
  // answers values past the constants as invalid.
  req.command = in.ConsumeIntegral<std::uint8_t>();
  req.pattern = pattern.data();
  req.recording = recording.data();
  req.count = in.ConsumeIntegral<std::int32_t>();
  req.trigger = in.ConsumeIntegral<std::uint8_t>();
  req.delay_s = in.ConsumeFloatingPoint<double>();
  req.start_at.sec = in.ConsumeIntegral<std::int32_t>();
  req.start_at.nanosec = in.ConsumeIntegral<std::uint32_t>();
  req.cameras._maximum = req.cameras._length = static_cast<std::uint32_t>(camera_ptrs.size());
  req.cameras._buffer = camera_ptrs.data();
  req.cameras._release = false;
  req.motion_compensation = in.ConsumeIntegral<std::uint8_t>();

  try {
    if (!d.writer->write(req)) return 0;
  } catch (const sl::dds::Error&) {
    return 0;  // not serializable (an enum out of range: BAD_PARAMETER): never sent
  }
  bool accepted = false;
  std::size_t reason_bytes = 0;
  const bool replied = d.awaitReply(client, req.request_id, client.size() <= 256 ? 1000ms : 20ms,
                                    accepted, reason_bytes);
  // A reply's reason is bounded whatever the request carried. (A missing
  // reply is no finding by itself: beyond 256 recent client ids, new ids
  // share one rate bucket, and rate-limited requests are counted, not
  // answered.)
  if (replied && reason_bytes > 1024) __builtin_trap();
  if (replied && accepted && req.command == sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START) {
    msg::Request stop{};
    std::string stop_client = "fuzz-stop";
    stop.client_id = stop_client.data();
    stop.request_id = d.next_id++;
    stop.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP;
    std::string empty;
    stop.pattern = stop.recording = empty.data();
    d.writer->write(stop);
    d.awaitReply(stop_client, stop.request_id, 3000ms, accepted, reason_bytes);
  }
  return 0;
}
