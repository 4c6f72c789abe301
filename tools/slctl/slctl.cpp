// slctl: command-line client of a running sl_sensord (over DDS).
//
//   slctl scan --count N --out DIR [--pattern NAME] [--units m|mm] [start options]
//   slctl start [--pattern NAME] [start options] | stop | status | patterns | pattern set NAME
// Start options: --trigger hardware|software, --delay S | --at UNIX_SECONDS,
// --cameras ID[,ID...], --motion on|off.
// Common options: --domain N, --ns NAMESPACE, --timeout SECONDS.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include "common/cli.h"
#include "common/ply.h"
#include "sl/client/client.h"
#include "sl/dds/dds.h"

namespace {

using namespace std::chrono_literals;
using sl::client::Command;
using sl::client::SensorClient;

constexpr const char* kUsage =
    "usage: slctl [options] COMMAND\n"
    "commands:\n"
    "  scan --count N --out DIR [--pattern NAME] [--units m|mm] [--format ply|pcd]\n"
    "                     take N scans, write DIR/scan_0001.ply ... (binary PLY: finite\n"
    "                     points; binary PCD: organized, NaN for invalid pixels), in\n"
    "                     metres as the topics (--units mm: millimetres)\n"
    "  start [--pattern NAME]  scan continuously until stop\n"
    "  record NAME [--count N] [--pattern P] [--wait]  scan and record the image sets\n"
    "                     under NAME (in the daemon's runtime.recording_root, printed)\n"
    "                     until N scans (default: until 'slctl stop'); --wait returns\n"
    "                     when the recording has ended; replay with sensor: replay\n"
    "  stop               stop scanning\n"
    "  status             print the daemon's status\n"
    "  patterns           list the daemon's patterns\n"
    "  config             print the daemon's configuration file\n"
    "  watch [--count N]  print the status every second (N lines, default until Ctrl-C)\n"
    "  pattern set NAME   select the pattern for the next scans\n"
    "start options (scan, start, record; default: as the daemon is configured):\n"
    "  --trigger MODE     hardware (trigger board / projector) or software (project\n"
    "                     pattern i, wait, grab: no trigger board needed, slower)\n"
    "  --delay S          start S seconds after the request\n"
    "  --at T             start at time T (Unix seconds, e.g. $(date -d '+5 sec' +%s))\n"
    "  --cameras A[,B]    triangulate with these of the pattern's cameras only\n"
    "  --motion on|off    motion compensation for this request\n"
    "options:\n"
    "  --domain N         DDS domain id (default 0)\n"
    "  --ns NAME          topic namespace (default sl)\n"
    "  --timeout S        seconds to wait for the daemon and each reply/scan (default 10)\n"
    "exit codes: 0 ok, 1 error, 2 usage, 3 no daemon answered, 4 request rejected\n";

struct Args {
  std::string command;
  std::vector<std::string> positional;
  int domain = 0;
  std::string ns = "sl";
  double timeout_s = 10;
  int count = 1;
  std::string out;
  std::string pattern;
  sl::tools::LengthUnit unit = sl::tools::LengthUnit::kMetre;  // files as the topics: metres
  bool pcd = false;
  sl::client::StartRequest start;  // options of scan / start / record
  bool start_options_given = false;
  bool wait = false;                // record: until the recording has ended
  std::set<std::string> options;    // every option given, to check it fits the command
};

// The options each command takes besides --domain, --ns and --timeout.
bool optionFits(const std::string& command, const std::string& option) {
  static const std::set<std::string> start = {"--trigger", "--delay", "--at", "--cameras", "--motion"};
  if (option == "--domain" || option == "--ns" || option == "--timeout") return true;
  if (command == "scan")
    return start.count(option) || option == "--count" || option == "--out" ||
           option == "--pattern" || option == "--units" || option == "--format";
  if (command == "start") return start.count(option) || option == "--pattern";
  if (command == "record")
    return start.count(option) || option == "--count" || option == "--pattern" || option == "--wait";
  if (command == "watch") return option == "--count";
  return false;
}

std::vector<std::string> splitCommas(const std::string& text) {
  std::vector<std::string> parts;
  std::size_t begin = 0;
  while (begin <= text.size()) {
    const std::size_t end = std::min(text.find(',', begin), text.size());
    parts.push_back(text.substr(begin, end - begin));
    begin = end + 1;
  }
  return parts;
}

[[noreturn]] void usageError(const std::string& message) {
  std::cerr << "slctl: " << message << "\n" << kUsage;
  std::exit(2);
}

int parseInt(const std::string& option, const std::string& value) {
  if (const auto v = sl::tools::toInt(value)) return *v;
  usageError(option + " expects an integer, not '" + value + "'");
}

Args parseArgs(int argc, char** argv) {
  Args args;
  bool count_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usageError(a + " needs a value");
      return argv[++i];
    };
    if (a.size() > 1 && a[0] == '-') args.options.insert(a);
    if (a == "--help" || a == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (a == "--wait") {
      args.wait = true;
    } else if (a == "--domain") {
      args.domain = parseInt(a, value());
      // DDS domain ids the default RTPS port mapping can address (0..230).
      if (args.domain < 0 || args.domain > 230)
        usageError("--domain expects 0..230, not " + std::to_string(args.domain));
    } else if (a == "--ns") {
      args.ns = value();
    } else if (a == "--timeout") {
      const std::string v = value();
      const auto seconds = sl::tools::toNumber(v);
      if (!seconds) usageError("--timeout expects seconds, not '" + v + "'");
      args.timeout_s = *seconds;
      if (!(args.timeout_s > 0 && args.timeout_s <= 86400))
        usageError("--timeout must be > 0 and at most 86400 s, not '" + v + "'");
    } else if (a == "--count") {
      args.count = parseInt(a, value());
      count_given = true;
    } else if (a == "--out") {
      args.out = value();
    } else if (a == "--pattern") {
      args.pattern = value();
    } else if (a == "--format") {
      const std::string v = value();
      if (v == "ply") args.pcd = false;
      else if (v == "pcd") args.pcd = true;
      else usageError("--format must be ply or pcd, not '" + v + "'");
    } else if (a == "--trigger") {
      const std::string v = value();
      if (v == "hardware") args.start.trigger = sl::client::TriggerMode::kHardware;
      else if (v == "software") args.start.trigger = sl::client::TriggerMode::kSoftware;
      else usageError("--trigger must be hardware or software, not '" + v + "'");
      args.start_options_given = true;
    } else if (a == "--delay") {
      const std::string v = value();
      const auto seconds = sl::tools::toNumber(v);
      if (!seconds || !(*seconds >= 0)) usageError("--delay expects seconds >= 0, not '" + v + "'");
      args.start.delay_s = *seconds;
      args.start_options_given = true;
    } else if (a == "--at") {
      const std::string v = value();
      const auto seconds = sl::tools::toNumber(v);
      // Checked before the conversion to int64 ns, which overflows past 9.2e9 s
      // (the daemon takes at most an hour ahead and says so).
      if (!seconds || !(*seconds > 0 && *seconds < 9.2e9))
        usageError("--at expects Unix seconds (before the year 2261), not '" + v + "'");
      args.start.start_at_ns = static_cast<std::int64_t>(*seconds * 1e9);
      args.start_options_given = true;
    } else if (a == "--cameras") {
      const std::string v = value();
      args.start.cameras = splitCommas(v);
      for (const auto& id : args.start.cameras)
        if (id.empty()) usageError("--cameras expects ID[,ID...], not '" + v + "'");
      args.start_options_given = true;
    } else if (a == "--motion") {
      const std::string v = value();
      if (v == "on") args.start.motion_compensation = true;
      else if (v == "off") args.start.motion_compensation = false;
      else usageError("--motion must be on or off, not '" + v + "'");
      args.start_options_given = true;
    } else if (a == "--units") {
      const std::string v = value();
      if (v == "mm") args.unit = sl::tools::LengthUnit::kMillimetre;
      else if (v == "m") args.unit = sl::tools::LengthUnit::kMetre;
      else usageError("--units must be mm or m, not '" + v + "'");
    } else if (!a.empty() && a[0] == '-') {
      usageError("unknown option '" + a + "'");
    } else if (args.command.empty()) {
      args.command = a;
    } else {
      args.positional.push_back(a);
    }
  }
  if (args.command.empty()) usageError("no command given");
  for (const auto& option : args.options)
    if (!optionFits(args.command, option))
      usageError("option " + option + " does not go with '" + args.command + "'");
  const std::size_t positionals = args.command == "record" ? 1 : args.command == "pattern" ? 2 : 0;
  if (args.positional.size() > positionals)
    usageError("'" + args.command + "' does not take '" + args.positional[positionals] + "'");
  // watch and record run until stopped unless --count is given.
  if ((args.command == "watch" || args.command == "record") && !count_given) args.count = 0;
  if (args.start_options_given && args.command != "scan" && args.command != "start" &&
      args.command != "record")
    usageError("--trigger, --delay, --at, --cameras and --motion go with scan, start or record");
  if (args.start.delay_s > 0 && args.start.start_at_ns != 0) usageError("give --delay or --at, not both");
  return args;
}

std::chrono::milliseconds toMs(double seconds) {
  return std::chrono::milliseconds(static_cast<long long>(seconds * 1000));
}

int noDaemon(const Args& args) {
  std::cerr << "slctl: no sl_sensord answered on 'rq/" << args.ns << "/commandRequest' (domain "
            << args.domain << ") within " << args.timeout_s
            << " s; is the daemon running with the same domain and namespace?\n";
  return 3;
}

// Sends a request and reports a rejection; returns the exit code (0 = accepted).
int sendCommand(SensorClient& client, const Args& args, Command command,
                const std::string& pattern, int count,
                sl::client::CommandReplyInfo* reply_out = nullptr) {
  const auto reply = client.request(command, pattern, count, toMs(args.timeout_s));
  if (!reply) {
    std::cerr << "slctl: the daemon did not reply within " << args.timeout_s << " s\n";
    return 3;
  }
  if (reply_out) *reply_out = *reply;
  if (!reply->accepted) {
    std::cerr << "slctl: request rejected (" << sl::client::toString(reply->code)
              << "): " << reply->reason << "\n";
    return 4;
  }
  return 0;
}

// Sends a START with the request's options; returns the exit code (0 = accepted).
int sendStart(SensorClient& client, const Args& args, const std::string& recording, int count,
              std::string* accepted_note = nullptr) {
  sl::client::StartRequest request = args.start;
  request.pattern = args.pattern;
  request.count = count;
  request.recording = recording;
  const auto reply = client.start(request, toMs(args.timeout_s));
  if (!reply) {
    std::cerr << "slctl: the daemon did not reply within " << args.timeout_s << " s\n";
    return 3;
  }
  if (!reply->accepted) {
    std::cerr << "slctl: request rejected (" << sl::client::toString(reply->code)
              << "): " << reply->reason << "\n";
    return 4;
  }
  if (accepted_note) *accepted_note = reply->reason;
  return 0;
}

// Seconds from now until a delayed request starts (0 without a delay).
double secondsUntilStart(const Args& args) {
  if (args.start.start_at_ns != 0)
    return std::max(0.0, (args.start.start_at_ns - sl::pipeline::systemClockNs()) * 1e-9);
  return args.start.delay_s;
}

void progressBar(int done, int total) {
  constexpr int kWidth = 30;
  const int filled = total > 0 ? done * kWidth / total : 0;
  std::fprintf(stderr, "\r[%s%s] %d/%d", std::string(filled, '#').c_str(),
               std::string(kWidth - filled, '.').c_str(), done, total);
  std::fflush(stderr);
}

int scan(SensorClient& client, const Args& args) {
  if (args.count < 1) usageError("scan --count must be >= 1");
  if (args.out.empty()) usageError("scan needs --out DIR");
  std::error_code error;
  std::filesystem::create_directories(args.out, error);
  if (error) {
    std::cerr << "slctl: cannot create output directory '" << args.out << "': " << error.message()
              << "\n";
    return 1;
  }
  const std::int64_t requested_at = sl::pipeline::systemClockNs();
  if (const int rc = sendStart(client, args, "", args.count)) return rc;
  // The first scan may wait for a delayed start.
  double wait_s = args.timeout_s + secondsUntilStart(args);
  const char* unit = args.unit == sl::tools::LengthUnit::kMetre ? "m" : "mm";
  // A progress bar on a terminal (stderr), for multi-scan requests.
  const bool show_progress = args.count > 1 && ::isatty(STDERR_FILENO);
  if (show_progress) progressBar(0, args.count);
  const double scale = args.unit == sl::tools::LengthUnit::kMetre ? 1e-3 : 1.0;
  // A request the daemon ended with an error (a decode that does not fit
  // the pattern: docs/decode-health.md) delivers no more clouds: its status
  // says so, and the wait ends there instead of at the timeout.
  auto endedWithError = [&]() -> std::optional<std::string> {
    const auto s = client.status(std::chrono::milliseconds(1));
    if (!s || s->state == sl::client::ScanState::kScanning || s->state == sl::client::ScanState::kDegraded ||
        s->state == sl::client::ScanState::kWaiting || s->last_error.empty() || s->last_error_ns < requested_at)
      return std::nullopt;
    return s->last_error;
  };
  for (int i = 1; i <= args.count; ++i) {
    std::optional<sl::pipeline::PointCloud> cloud;
    const auto until = std::chrono::steady_clock::now() + toMs(wait_s);
    std::optional<std::string> ended;
    while (!cloud && !ended && std::chrono::steady_clock::now() < until) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now());
      cloud = client.receiveCloud(requested_at, std::min<std::chrono::milliseconds>(left, std::chrono::milliseconds(250)));
      if (!cloud) ended = endedWithError();
    }
    if (ended) {
      if (show_progress) std::fputs("\n", stderr);
      std::cerr << "slctl: scan " << i << " of " << args.count << ": the daemon ended the request: " << *ended
                << "\n";
      return 1;
    }
    if (!cloud) {
      std::cerr << "slctl: scan " << i << " of " << args.count << " did not arrive within "
                << wait_s << " s";
      if (const auto s = client.status(1s); s && !s->last_error.empty())
        std::cerr << " (daemon: " << s->last_error << ")";
      std::cerr << "\n";
      return 1;
    }
    char name[32];
    std::snprintf(name, sizeof name, "scan_%04d.%s", i, args.pcd ? "pcd" : "ply");
    const std::string path = (std::filesystem::path(args.out) / name).string();
    const std::size_t written = args.pcd ? sl::tools::writePcd(*cloud, path, args.unit)
                                         : sl::tools::writePly(*cloud, path, args.unit);
    double zmin = std::numeric_limits<double>::infinity(), zmax = -zmin, zsum = 0;
    for (const auto& p : cloud->points) {
      if (!std::isfinite(p.z)) continue;
      zmin = std::min<double>(zmin, p.z);
      zmax = std::max<double>(zmax, p.z);
      zsum += p.z;
    }
    const double total = static_cast<double>(cloud->points.size());
    if (show_progress) std::fputs("\r\033[K", stderr);  // the bar gives way to the line
    if (written > 0) {
      // 0.1 mm either way.
      const int digits = args.unit == sl::tools::LengthUnit::kMetre ? 4 : 1;
      std::printf("scan %d/%d: %dx%d, %zu valid points (%.1f %%), z %.*f..%.*f mean %.*f %s -> %s\n",
                  i, args.count, cloud->width, cloud->height, written, 100.0 * written / total,
                  digits, zmin * scale, digits, zmax * scale, digits, zsum / written * scale, unit,
                  path.c_str());
    } else {
      std::printf("scan %d/%d: %dx%d, no valid points -> %s\n", i, args.count, cloud->width,
                  cloud->height, path.c_str());
    }
    std::fflush(stdout);
    if (show_progress) progressBar(i, args.count);
    wait_s = args.timeout_s;
  }
  if (show_progress) std::fputs("\n", stderr);
  return 0;
}

// The engine fields (sl/client/status_fields.h) printStatus formats in
// lines of its own; every other one gets a "label: value" line.
const std::set<std::string> kStatusFieldsFormatted = {
    "scans_done", "scans_requested", "scan_rate_hz", "frame_rate_hz", "frames_dropped",
    "sets_incomplete", "frames_overflow", "frames_unmatched", "sets_overflow",
    "sets_not_recorded", "sets_recorded", "sets_over_quota", "errors_reported", "latency_ms",
    "latency_max_ms", "wait_ms", "processing_ms", "publish_ms", "decode_modulated_fraction",
    "decode_consistent_fraction", "decode_residual_median", "clouds_implausible", "adaptive_switches"};

void printStatusLine(const char* label, std::uint64_t v) {
  std::printf("%-18s%llu\n", (std::string(label) + ":").c_str(), static_cast<unsigned long long>(v));
}
void printStatusLine(const char* label, double v) {
  std::printf("%-18s%.3g\n", (std::string(label) + ":").c_str(), v);
}

int printStatus(SensorClient& client, const Args& args) {
  const auto s = client.status(toMs(args.timeout_s));
  if (!s) return noDaemon(args);
  std::printf("state:            %s\n", sl::client::toString(s->state));
  if (s->state == sl::client::ScanState::kDegraded)
    std::printf("degraded:         %s\n", s->degraded_reason.c_str());
  std::printf("pattern:          %s\n", s->pattern.c_str());
  std::printf("scans:            %llu of %s\n", static_cast<unsigned long long>(s->scans_done),
              s->scans_requested ? std::to_string(s->scans_requested).c_str() : "continuous");
  if (s->state == sl::client::ScanState::kWaiting)
    std::printf("starts in:        %.1f s\n",
                (s->start_at_ns - sl::pipeline::systemClockNs()) * 1e-9);
  std::printf("trigger:          %s\n", sl::client::toString(s->trigger));
  std::string cameras;
  for (const auto& id : s->cameras) cameras += (cameras.empty() ? "" : ", ") + id;
  std::printf("cameras:          %s\n", cameras.c_str());
  std::printf("motion comp.:     %s\n", s->motion_compensation ? "on" : "off");
  std::printf("scan rate:        %.2f Hz\n", s->scan_rate_hz);
  std::printf("frame rate:       %.1f Hz\n", s->frame_rate_hz);
  if (s->latency_ms > 0)
    std::printf("latency:          %.1f ms median, %.1f ms max (last trigger -> published; "
                "wait %.1f, processing %.1f, publishing %.1f ms)\n",
                s->latency_ms, s->latency_max_ms, s->wait_ms, s->processing_ms, s->publish_ms);
  else
    std::printf("latency:          - (no scan yet)\n");
  auto u = [](std::uint64_t v) { return static_cast<unsigned long long>(v); };
  std::printf("frames dropped:   %llu (queue full %llu, unmatched %llu)\n", u(s->frames_dropped),
              u(s->frames_overflow), u(s->frames_unmatched));
  std::printf("sets dropped:     %llu (queue full %llu, write timed out %llu, not recorded %llu)\n",
              u(s->sets_dropped), u(s->sets_overflow), u(s->writes_timed_out),
              u(s->sets_not_recorded));
  std::printf("sets incomplete:  %llu\n", u(s->sets_incomplete));
  if (!s->adaptive_mode.empty() || s->adaptive_switches > 0)
    std::printf("adaptive:         %s%s%s (%llu switches)\n",
                s->adaptive_mode.empty() ? "-" : s->adaptive_mode.c_str(),
                s->adaptive_reason.empty() ? "" : ": ", s->adaptive_reason.c_str(),
                u(s->adaptive_switches));
  std::printf("decode health:    %.1f %% modulated, %.1f %% of those consistent, residual median "
              "%.3f; %llu implausible clouds\n",
              100 * s->decode_modulated_fraction, 100 * s->decode_consistent_fraction,
              s->decode_residual_median, u(s->clouds_implausible));
  std::printf("recording:        %s (%llu sets recorded, %llu over quota)\n",
              s->recording.empty() ? "-" : s->recording.c_str(), u(s->sets_recorded),
              u(s->sets_over_quota));
  if (s->last_error.empty()) {
    std::printf("last error:       -\n");
  } else {
    std::printf("last error:       %s (%.1f s ago)\n", s->last_error.c_str(),
                (sl::pipeline::systemClockNs() - s->last_error_ns) * 1e-9);
  }
  std::printf("errors reported:  %llu\n", u(s->errors_reported));
#define SL_PRINT_FIELD(type, name, label) \
  if (!kStatusFieldsFormatted.count(#name)) printStatusLine(label, s->name);
  SL_STATUS_ENGINE_FIELDS(SL_PRINT_FIELD)
#undef SL_PRINT_FIELD
  std::printf("requests:         %llu (answered %llu, rate-limited %llu, invalid %llu, reply timed out %llu)\n",
              u(s->requests_received), u(s->requests_answered), u(s->requests_rate_limited),
              u(s->requests_invalid), u(s->replies_timed_out));
  std::printf("requests malformed: %llu, refused by the full request reader: %llu\n",
              u(s->requests_malformed), u(s->requests_rejected));
  std::printf("clouds lost to readers: %llu\n", u(s->clouds_lost_to_readers));
  std::printf("images not compressed: %llu (scans whose compressed images a matched reader did not get)\n",
              u(s->images_not_compressed));
  for (const auto& r : s->points_readers)
    std::printf("  points reader %s: %s, %llu clouds lost\n", r.guid.c_str(),
                !r.reliable          ? "best effort (losses not visible to the daemon)"
                : r.acknowledging    ? "acknowledging"
                                     : "NOT acknowledging",
                u(r.clouds_lost));
  return 0;
}

// Prints one status line per second until the daemon stops answering,
// `--count` lines were printed (0 = until Ctrl-C), or a signal ends slctl.
int watch(SensorClient& client, const Args& args) {
  int printed = 0;
  while (args.count <= 0 || printed < args.count) {
    const auto s = client.status(toMs(std::max(args.timeout_s, 2.0)));
    if (!s) return noDaemon(args);
    const std::string of =
        s->scans_requested ? std::to_string(s->scans_requested) : std::string("continuous");
    std::printf("%-8s %-20s %-8s scans %6llu of %-10s rate %5.2f Hz frames %5.1f Hz  dropped "
                "frames %llu sets %llu  incomplete %llu%s%s\n",
                sl::client::toString(s->state), s->pattern.c_str(), sl::client::toString(s->trigger),
                static_cast<unsigned long long>(s->scans_done), of.c_str(), s->scan_rate_hz,
                s->frame_rate_hz,
                static_cast<unsigned long long>(s->frames_dropped),
                static_cast<unsigned long long>(s->sets_dropped),
                static_cast<unsigned long long>(s->sets_incomplete),
                s->last_error.empty() ? "" : "  error: ", s->last_error.c_str());
    std::fflush(stdout);
    ++printed;
    // Status arrives on every change (each scan); show the latest once a second.
    std::this_thread::sleep_for(1s);
  }
  return 0;
}

// Waits until the daemon's recording has ended (its count reached, a stop or
// a quota) and it is idle again; 1 when the daemon makes no progress for
// --timeout, 3 when it stops answering.
int waitForRecording(SensorClient& client, const Args& args, std::uint64_t sets_before) {
  bool seen = false;
  std::uint64_t settled_count = sets_before;
  auto settled_since = std::chrono::steady_clock::now();
  std::uint64_t progress = 0;
  auto last_progress = std::chrono::steady_clock::now();
  const auto stall = toMs(args.timeout_s + secondsUntilStart(args));
  for (;;) {
    const auto s = client.status(toMs(args.timeout_s));
    if (!s) return noDaemon(args);
    if (s->recording == args.positional[0]) seen = true;
    const bool idle = s->state == sl::client::ScanState::kIdle && s->recording.empty();
    // The recorder's thread may still write queued sets after the request
    // ended: done once the count held for two status periods.
    if (!idle || s->sets_recorded != settled_count) {
      settled_count = s->sets_recorded;
      settled_since = std::chrono::steady_clock::now();
    }
    const bool settled = std::chrono::steady_clock::now() - settled_since > 2s;
    if (idle && settled && (seen || s->sets_recorded != sets_before)) {
      // sets_recorded counts every recording of the daemon's life.
      std::printf("recorded %llu image sets\n",
                  static_cast<unsigned long long>(s->sets_recorded - sets_before));
      if (!s->last_error.empty()) std::printf("daemon: %s\n", s->last_error.c_str());
      return 0;
    }
    if (s->state == sl::client::ScanState::kError) {
      std::cerr << "slctl: the recording ended in an error: " << s->last_error << "\n";
      return 1;
    }
    if (s->sets_recorded + s->scans_done != progress) {
      progress = s->sets_recorded + s->scans_done;
      last_progress = std::chrono::steady_clock::now();
    } else if (std::chrono::steady_clock::now() - last_progress > stall) {
      std::cerr << "slctl: the recording made no progress for " << args.timeout_s << " s\n";
      return 1;
    }
    std::this_thread::sleep_for(200ms);
  }
}

int run(const Args& args) {
  sl::client::ClientOptions options;
  options.domain_id = args.domain;
  options.ns = args.ns;
  options.subscribe_points = args.command == "scan";
  SensorClient client(options);
  if (args.command == "status") return printStatus(client, args);
  if (args.command == "watch") return watch(client, args);
  if (!client.waitForDaemon(toMs(args.timeout_s))) return noDaemon(args);
  if (args.command == "scan") return scan(client, args);
  if (args.command == "start") {
    const int rc = sendStart(client, args, "", 0);
    if (rc == 0) std::printf("scanning continuously; 'slctl stop' ends it\n");
    return rc;
  }
  if (args.command == "record") {
    if (args.positional.size() != 1) usageError("usage: slctl record NAME [--count N]");
    const int count = args.count;
    if (count < 0) usageError("record --count must be >= 0");
    // The status before the request: a recording too short to be seen
    // running still changes its set count.
    const auto before = args.wait ? client.status(toMs(args.timeout_s)) : std::nullopt;
    std::string note;
    if (const int rc = sendStart(client, args, args.positional[0], count, &note)) return rc;
    // The daemon names the folder in its reply ("recording to DIR").
    const std::string prefix = "recording to ";
    const std::string where =
        note.rfind(prefix, 0) == 0 ? note.substr(prefix.size()) : "runtime.recording_root";
    std::printf("recording '%s' to %s (%s)%s\n", args.positional[0].c_str(), where.c_str(),
                count ? (std::to_string(count) + " scans").c_str() : "until stop",
                args.wait ? "" : "; 'slctl stop' ends it");
    std::fflush(stdout);
    return args.wait ? waitForRecording(client, args, before ? before->sets_recorded : 0) : 0;
  }
  if (args.command == "stop") {
    const int rc = sendCommand(client, args, Command::kStop, "", 0);
    if (rc == 0) std::printf("stopped\n");
    return rc;
  }
  if (args.command == "patterns") {
    sl::client::CommandReplyInfo reply;
    if (const int rc = sendCommand(client, args, Command::kListPatterns, "", 0, &reply)) return rc;
    for (const auto& name : reply.patterns) std::printf("%s\n", name.c_str());
    return 0;
  }
  if (args.command == "config") {
    sl::client::CommandReplyInfo reply;
    if (const int rc = sendCommand(client, args, Command::kGetConfig, "", 0, &reply)) return rc;
    std::fputs(reply.detail.c_str(), stdout);
    return 0;
  }
  if (args.command == "pattern") {
    if (args.positional.size() != 2 || args.positional[0] != "set")
      usageError("usage: slctl pattern set NAME");
    const int rc = sendCommand(client, args, Command::kSetPattern, args.positional[1], 0);
    if (rc == 0) std::printf("pattern set to '%s'\n", args.positional[1].c_str());
    return rc;
  }
  usageError("unknown command '" + args.command + "'");
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parseArgs(argc, argv);
  sl::dds::retainLargeSampleMemory();  // `scan` and `start` receive clouds
  try {
    return run(args);
  } catch (const std::exception& e) {
    std::cerr << "slctl: " << e.what() << "\n";
    return 1;
  }
}
