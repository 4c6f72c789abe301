// sl_view: see what the sensor sees.
//
//   sl_view [--host 127.0.0.1] [--port 8765] ...   Foxglove WebSocket bridge + web page
//   sl_view record FILE.mcap [--count N] ...      the daemon's topics into an MCAP file
//
// The bridge subscribes to the daemon's DDS topics and forwards each sample's
// CDR bytes unchanged to Foxglove (foxglove.websocket.v1, ros2msg schemas,
// cdr encoding); the same port serves the built-in web page (tools/sl_view/web)
// with three.js from npm, and a /sl/command service (JSON) that sends
// requests on the daemon's request topic exactly as slctl does.
#include <json/json.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include "common/cdr.h"
#include "common/ros2_schemas.h"
#include "foxglove_server.h"
#include "mcap_record.h"
#include "options.h"
#include "preview.h"
#include "raw_topics.h"
#include "sl/client/client.h"
#include "sl/dds/dds.h"

#ifndef SL_VIEW_WEB_DIR
#define SL_VIEW_WEB_DIR "tools/sl_view/web"
#endif
#ifndef SL_VIEW_THREE_DIR
#define SL_VIEW_THREE_DIR "tools/sl_view/node_modules/three"
#endif

namespace {

using sl::view::ArgCursor;
using sl::view::parseTopicOption;

std::atomic<bool> g_stop{false};
void onSignal(int) { g_stop = true; }

const char* kUsage =
    "usage: sl_view [options]                 live view: Foxglove bridge + web page\n"
    "       sl_view record FILE.mcap [options] record the daemon's topics as MCAP (ROS 2)\n"
    "options (both):\n"
    "  --domain N        DDS domain (default 0)\n"
    "  --ns NAME         the daemon's namespace (default sl)\n"
    "  --reliable        read clouds and images reliably (the default; keep-last 1\n"
    "                    for the live view, 8 for record): lost fragments are\n"
    "                    repaired; a stopped sl_view does not block the daemon\n"
    "  --best-effort     read them best-effort: never repaired; a cloud whose burst\n"
    "                    overflows the socket receive buffer (net.core.rmem_max) is\n"
    "                    lost (counted in GET /stats and on the page)\n"
    "live view:\n"
    "  --host ADDR       listen address (default 127.0.0.1; 0.0.0.0 = every interface)\n"
    "  --port N          TCP port (default 8765; 0 = any free port)\n"
    "  --queue N         messages queued per viewer subscription (default 2; the\n"
    "                    oldest is dropped and counted when full)\n"
    "  --decimate N      the web page's cloud: every Nth pixel per direction (default 4)\n"
    "  --web-dir DIR     the page's files (default: installed ../share/sl-sensor/sl_view/web\n"
    "                    beside the binary, else the source tree's tools/sl_view/web)\n"
    "  --three-dir DIR   three.js from npm (default: installed .../sl_view/three, else\n"
    "                    tools/sl_view/node_modules/three)\n"
    "record:\n"
    "  --topics A,B      ROS topic names to record (default: all but image sets and maps)\n"
    "  --count N         stop after N clouds (default: until Ctrl-C or --seconds)\n"
    "  --seconds S       stop after S seconds\n"
    "  --scan N          also ask the daemon for N scans (as `slctl scan --count N`);\n"
    "                    0: scan continuously, stopped after --count clouds\n"
    "  --compression C   chunk compression: zstd (default), lz4 or none\n"
    "  --buffer-mb N     samples taken but not yet written, at most N MB (default\n"
    "                    1024); beyond, samples are dropped, named, exit code 5\n"
    "  a scan's images and camera_info missing from the file are named (exit code 5)\n";

int usage(const std::string& error) {
  std::cerr << "sl_view: " << error << "\n" << kUsage;
  return 2;
}

std::string requestJson(const std::string& text, sl::client::SensorClient& client) {
  Json::Value req;
  Json::CharReaderBuilder b;
  std::string errors;
  std::istringstream in(text);
  if (!Json::parseFromStream(b, in, &req, &errors) || !req.isObject())
    throw std::runtime_error("request is not a JSON object: " + errors);
  const std::string command = req.get("command", "").asString();
  const std::string pattern = req.get("pattern", "").asString();
  const int count = req.get("count", 0).asInt();
  using sl::client::Command;
  std::optional<sl::client::CommandReplyInfo> reply;
  const auto timeout = std::chrono::milliseconds(5000);
  if (command == "start") {
    reply = client.request(Command::kStart, pattern, count, timeout);
  } else if (command == "scan") {
    reply = client.request(Command::kStart, pattern, count > 0 ? count : 1, timeout);
  } else if (command == "stop") {
    reply = client.request(Command::kStop, "", 0, timeout);
  } else if (command == "set_pattern") {
    reply = client.request(Command::kSetPattern, pattern, 0, timeout);
  } else if (command == "list_patterns") {
    reply = client.request(Command::kListPatterns, "", 0, timeout);
  } else {
    throw std::runtime_error("unknown command '" + command +
                             "' (start, scan, stop, set_pattern, list_patterns)");
  }
  if (!reply) throw std::runtime_error("no daemon answered '" + command + "' within 5 s");
  Json::Value out;
  out["command"] = command;
  out["accepted"] = reply->accepted;
  out["code"] = sl::client::toString(reply->code);
  out["reason"] = reply->reason;
  out["patterns"] = Json::Value(Json::arrayValue);
  for (const auto& p : reply->patterns) out["patterns"].append(p);
  Json::StreamWriterBuilder w;
  w["indentation"] = "";
  return Json::writeString(w, out);
}

// The page's files: installed beside the binary (bin/../share/sl-sensor/
// sl_view, by cmake --install) or, in a build tree, the source tree's.
std::pair<std::string, std::string> defaultAssetDirs() {
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const auto installed = exe.parent_path().parent_path() / "share/sl-sensor/sl_view";
    if (std::filesystem::exists(installed / "web/index.html", ec))
      return {(installed / "web").string(), (installed / "three").string()};
  }
  return {SL_VIEW_WEB_DIR, SL_VIEW_THREE_DIR};
}

int serve(int argc, char** argv) {
  sl::view::ServerOptions server;
  sl::view::RawTopicsOptions topics;
  int decimate = 4;
  auto [web_dir, three_dir] = defaultAssetDirs();
  for (ArgCursor args(argc, argv, 1); args.next();) {
    const std::string a = args.option();
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (parseTopicOption(args, topics)) continue;
    else if (a == "--host") server.host = args.value();
    else if (a == "--port") server.port = args.integer(0, 65535);
    else if (a == "--queue") server.queue_depth = static_cast<std::size_t>(args.integer(1, 64));
    else if (a == "--decimate") decimate = args.integer(1, 64);
    else if (a == "--web-dir") web_dir = args.value();
    else if (a == "--three-dir") three_dir = args.value();
    else throw std::invalid_argument("unknown option '" + a + "'");
  }
  if (!std::filesystem::exists(three_dir + "/build/three.module.js"))
    std::cerr << "sl_view: warning: " << three_dir
              << "/build/three.module.js not found: the web page needs three.js from npm "
                 "(`npm ci` in tools/sl_view, done by scripts/install-deps.sh); "
                 "Foxglove works without it\n";
  server.static_dirs = {{"/", web_dir}, {"/three/", three_dir}};

  topics.lazy = true;  // a topic is read only while a viewer subscribes to it
  sl::view::RawTopics raw(topics);
  std::vector<sl::view::ChannelInfo> channels;
  std::uint32_t next_id = 1;
  for (const auto& t : raw.topics()) {
    const auto& schema = sl::tools::ros2Schema(t.type_name);
    channels.push_back({next_id++, t.ros_name, "cdr", schema.name, schema.definition, "ros2msg"});
  }
  const std::size_t points_topic = 0;  // daemonTopics() lists the cloud first
  const std::uint32_t preview_channel = next_id++;
  {
    const auto& schema = sl::tools::ros2Schema("sensor_msgs/msg/PointCloud2");
    channels.push_back({preview_channel, "/" + topics.ns + "/points/preview", "cdr", schema.name,
                        schema.definition, "ros2msg"});
  }

  sl::client::SensorClient client(sl::view::clientOptions(topics));
  std::vector<sl::view::ServiceInfo> services;
  services.push_back({1, "/" + topics.ns + "/command", "sl_msgs/srv/Command",
                      [&client](const std::string& req) { return requestJson(req, client); }});

  // The DDS side, per topic: samples taken, and samples lost before sl_view
  // took them as Cyclone reports it (sample-lost: a best-effort sample with
  // a fragment missing; sample-rejected: no room in the reader's history).
  // Neither counts a sample overwritten in a keep-last history before it was
  // taken, nor (measured: 0 while 22 of 54 clouds never came) a best-effort
  // cloud that lost a fragment, so for the cloud the scans the daemon
  // published while the cloud was read (its status' scans_done) are set
  // against the clouds taken: the difference counts every cloud missed,
  // however (to within the one in flight when a status sample comes). Shown in GET /stats
  // ("dds") and on the page; written by this thread, read by the server's.
  const std::size_t status_topic = [&] {
    for (std::size_t i = 0; i < raw.topics().size(); ++i)
      if (raw.topics()[i].type_name == "sl_msgs/msg/Status") return i;
    return raw.topics().size();
  }();
  std::vector<std::uint64_t> taken(raw.topics().size(), 0), lost_before(raw.topics().size(), 0),
      rejected_before(raw.topics().size(), 0);
  std::uint64_t clouds_published = 0, clouds_taken = 0;  // while the cloud was read
  std::optional<std::uint64_t> last_scans_done;
  // Whether a daemon is behind the topics: it publishes its status at least
  // every dds.status_period_s (1 s by default) and on every change, so no
  // status for kDaemonGone means no daemon (it exited, or another --ns /
  // --domain). Said on stderr when it changes, and in GET /stats.
  constexpr auto kDaemonGone = std::chrono::seconds(5);
  const auto started = std::chrono::steady_clock::now();
  std::optional<std::chrono::steady_clock::time_point> last_status;
  enum class Daemon { kUnknown, kPresent, kAbsent } daemon = Daemon::kUnknown;
  std::mutex dds_stats_mutex;
  std::string dds_stats_json = "{}";  // guarded by dds_stats_mutex
  const auto ddsStats = [&] {
    Json::Value v;
    v["reliable"] = !topics.best_effort;
    v["topics"] = Json::Value(Json::arrayValue);
    for (std::size_t i = 0; i < raw.topics().size(); ++i) {
      Json::Value t;
      t["topic"] = raw.topics()[i].ros_name;
      t["reading"] = raw.active(i);
      t["taken"] = Json::UInt64(taken[i]);
      t["lost"] = Json::UInt64(lost_before[i] + raw.samplesLost(i));
      t["rejected"] = Json::UInt64(rejected_before[i] + raw.samplesRejected(i));
      v["topics"].append(t);
    }
    v["clouds_published_while_read"] = Json::UInt64(clouds_published);
    v["clouds_taken_while_read"] = Json::UInt64(clouds_taken);
    v["clouds_missed"] = Json::UInt64(clouds_published > clouds_taken ? clouds_published - clouds_taken : 0);
    v["daemon"] = daemon == Daemon::kPresent;
    v["status_age_s"] = last_status ? std::chrono::duration<double>(std::chrono::steady_clock::now() -
                                                                    *last_status).count()
                                    : -1.0;
    Json::StreamWriterBuilder w;
    w["indentation"] = "";
    return Json::writeString(w, v);
  };
  server.dds_stats = [&] {
    std::lock_guard<std::mutex> lock(dds_stats_mutex);
    return dds_stats_json;
  };

  sl::view::FoxgloveServer ws(server, channels, services);
  std::printf("sl_view: live view at http://%s:%d/  (Foxglove: ws://%s:%d)\n",
              server.host.c_str(), ws.port(), server.host.c_str(), ws.port());
  std::fflush(stdout);

  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  std::uint64_t preview_errors = 0;
  std::string last_preview_error;
  std::vector<std::uint32_t> incompatible(raw.topics().size(), 0);
  auto stats_at = std::chrono::steady_clock::now();
  while (!g_stop) {
    for (std::size_t i = 0; i < raw.topics().size(); ++i) {
      const bool wanted = ws.subscribed(static_cast<std::uint32_t>(i + 1)) ||
                          (i == points_topic && ws.subscribed(preview_channel));
      if (!wanted && raw.active(i) && i != status_topic) {  // its reader's counts go with it
        lost_before[i] += raw.samplesLost(i);
        rejected_before[i] += raw.samplesRejected(i);
        if (i == points_topic) last_scans_done.reset();
      }
      raw.setActive(i, wanted || i == status_topic);  // the status tells whether a daemon is there
      // A writer this reader cannot read would leave the topic silently empty.
      std::int32_t policy = 0;
      const std::uint32_t n = raw.incompatibleWriters(i, &policy);
      if (n > incompatible[i])
        std::cerr << "sl_view: warning: " << raw.topics()[i].ros_name
                  << ": a writer's QoS does not match this reader (policy id " << policy
                  << (topics.best_effort ? "" : "; try --best-effort") << ")\n";
      incompatible[i] = std::max(incompatible[i], n);
    }
    raw.poll(DDS_MSECS(100), [&](std::shared_ptr<const sl::view::RawSample> s) {
      const std::uint32_t channel = static_cast<std::uint32_t>(s->topic + 1);
      ++taken[s->topic];
      if (s->topic == status_topic) last_status = std::chrono::steady_clock::now();
      if (s->topic == points_topic) ++clouds_taken;
      if (s->topic == status_topic && raw.active(points_topic)) {
        try {
          sl::tools::CdrReader status(s->data(), s->size(), "status sample");
          status.i32();  // stamp
          status.u32();
          status.u32();     // state
          status.string();  // pattern
          const std::uint64_t scans_done = status.u64();
          // A new request starts scans_done again from 0.
          if (last_scans_done)
            clouds_published += scans_done >= *last_scans_done ? scans_done - *last_scans_done : scans_done;
          else
            clouds_taken = clouds_published;  // counting starts here
          last_scans_done = scans_done;
        } catch (const sl::tools::CdrError&) {
        }
      }
      if (s->topic == points_topic && ws.subscribed(preview_channel)) {
        try {
          auto bytes = std::make_shared<std::vector<std::uint8_t>>(
              sl::view::decimateCloud(s->bytes(), decimate));
          std::string_view view(reinterpret_cast<const char*>(bytes->data()), bytes->size());
          ws.publish({preview_channel, s->receive_ns, view, bytes});
        } catch (const sl::tools::CdrError& e) {
          if (preview_errors++ == 0 || last_preview_error != e.what())
            std::cerr << "sl_view: preview: " << e.what() << "\n";
          last_preview_error = e.what();
        }
      }
      if (ws.subscribed(channel)) ws.publish({channel, s->receive_ns, s->bytes(), s});
    });
    const auto now = std::chrono::steady_clock::now();
    const Daemon daemon_before = daemon;
    std::string said;  // written after /stats has the new state, so that both agree
    if (last_status && now - *last_status < kDaemonGone) {
      if (daemon != Daemon::kPresent) said = "sl_view: daemon found (status on rt/" + topics.ns + "/status)\n";
      daemon = Daemon::kPresent;
    } else if (daemon == Daemon::kPresent || (daemon == Daemon::kUnknown && now - started > kDaemonGone)) {
      said = "sl_view: no daemon: no status on rt/" + topics.ns + "/status (domain " +
             std::to_string(topics.domain_id) + ") for " +
             std::to_string(std::chrono::duration_cast<std::chrono::seconds>(kDaemonGone).count()) +
             " s; the page shows \"no daemon\" until one answers\n";
      daemon = Daemon::kAbsent;
    }
    // GET /stats follows a change of the daemon's state at once (a client that
    // read "daemon found" on stderr must not then read daemon=false), otherwise
    // twice a second.
    if (daemon != daemon_before || now - stats_at > std::chrono::milliseconds(500)) {
      stats_at = std::chrono::steady_clock::now();
      std::string json = ddsStats();
      std::lock_guard<std::mutex> lock(dds_stats_mutex);
      dds_stats_json = std::move(json);
    }
    if (!said.empty()) std::cerr << said << std::flush;
  }
  ws.stop();
  for (std::size_t i = 0; i < raw.topics().size(); ++i) {
    const std::uint64_t lost = lost_before[i] + raw.samplesLost(i),
                        rejected = rejected_before[i] + raw.samplesRejected(i);
    if (lost > 0 || rejected > 0)
      std::printf("sl_view: %s: %llu samples lost in DDS (best-effort: a fragment missing), "
                  "%llu rejected\n",
                  raw.topics()[i].ros_name.c_str(), static_cast<unsigned long long>(lost),
                  static_cast<unsigned long long>(rejected));
  }
  if (clouds_published > 0)
    std::printf("sl_view: %llu of the %llu clouds the daemon published while they were read "
                "were taken (%llu missed)\n",
                static_cast<unsigned long long>(std::min(clouds_taken, clouds_published)),
                static_cast<unsigned long long>(clouds_published),
                static_cast<unsigned long long>(clouds_published > clouds_taken
                                                    ? clouds_published - clouds_taken
                                                    : 0));
  const auto st = ws.stats();
  std::printf("sl_view: %llu messages sent, %llu dropped for slow viewers\n",
              static_cast<unsigned long long>(st.sent),
              static_cast<unsigned long long>(st.dropped));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  sl::dds::retainLargeSampleMemory();  // the clouds' memory stays for the next ones
  try {
    if (argc >= 2 && std::strcmp(argv[1], "record") == 0) {
      std::signal(SIGINT, onSignal);
      std::signal(SIGTERM, onSignal);
      return sl::view::recordMain(argc - 1, argv + 1, g_stop);
    }
    return serve(argc, argv);
  } catch (const std::invalid_argument& e) {
    return usage(e.what());
  } catch (const std::exception& e) {
    std::cerr << "sl_view: " << e.what() << "\n";
    return 1;
  }
}
