// sl_dds_bench: point-cloud throughput and latency over DDS between two
// processes on one machine, with the daemon's DDS layer (sl::dds), types
// (idl/) and cloud QoS. Run the subscriber first, then the publisher:
//
//   sl_dds_bench sub [--topic T] [--count N] [--timeout S]
//   sl_dds_bench pub [--topic T] [--count N] [--rate HZ] [--width W] [--height H]
//   sl_dds_bench listen [--topic T] [--duration S] [--timeout S] [--depth N] [--best-effort 1]
//                       [--prefault-clouds N] [--in-place 1]
//
// listen: a subscriber to the daemon's clouds (scripts/bench-delivery.sh):
// waits at most --timeout S (default 60) for the first cloud, then takes
// clouds for --duration S (default 30), reader reliable (or best effort)
// keep-last --depth (default 4), and prints one line per cloud,
// "rx <stamp> <take> <written> <faults> <woken>": header.stamp; CLOCK_REALTIME
// after the take; the source timestamp (the writer's clock at dds_write);
// the minor page faults of the take that returned the cloud; CLOCK_REALTIME
// before that take (after the wait-set woke), all in ns, then
// "listen: done <clouds>". Exits 1 if no cloud came. --prefault-clouds N
// first touches the heap memory of N full-size (1440 x 1080) clouds, so that
// the first samples taken do not page-fault (sl::dds::prefaultHeap; default
// 0); shared-memory mappings are always populated
// (sl::dds::populateSharedMemoryMappings). --in-place 1 takes each cloud
// serialized (dds_takecdr) and reads its header and layout in place, as
// sl_view does, instead of deserializing it into the generated struct (a
// 25 MB copy into memory of the taking thread); "<take>" is then after that
// read. "listen: done" also counts malformed clouds (in place only).
//
// The publisher waits (at most 10 s) for a reader, then writes N organized
// clouds of W x H points x 16 bytes (default 1440 x 1080, the sensor's) at
// HZ (0 = back to back), writer QoS as the daemon's rt/<ns>/points: reliable,
// a write blocks at most 200 ms (then the cloud counts as not sent), keep-last
// 4, XCDR1. header.stamp = CLOCK_REALTIME just before the write; the first 8
// bytes of data carry the sequence number.
// The subscriber (reliable, keep-last 8, like slctl) takes clouds until it has
// seen the last sequence number or no cloud came for --quiet S (default 3; a
// slow configuration needs more, or the clouds still on their way count as
// lost) or --timeout S passed, and prints: clouds received and lost (missing sequence numbers),
// clouds/s delivered (first to last receive), latency = receive time
// (CLOCK_REALTIME after the take, i.e. after deserialization) - header.stamp,
// median / p99 / max. Same machine, so the same clock on both sides.
// Uses CYCLONEDDS_URI like every Cyclone DDS program.
#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <sys/resource.h>

#include <dds/ddsc/dds_statistics.h>
#include <dds/ddsi/ddsi_serdata.h>

#include "common/point_cloud2_cdr.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/dds/dds.h"

namespace {

using Cloud = sensor_msgs_msg_dds__PointCloud2_;
using Field = sensor_msgs_msg_dds__PointField_;
namespace dds = sl::dds;

struct Args {
  std::string mode;
  std::string topic = "rt/sl_bench/points";
  long count = 100;
  double rate_hz = 5;
  std::uint32_t width = 1440, height = 1080;
  double timeout_s = 120;
  double quiet_s = 3;  // sub: ends after this long without a cloud
  double duration_s = 30;
  int depth = 4;
  bool best_effort = false;
  long prefault_clouds = 0;
  bool in_place = false;
};

[[noreturn]] void usage(const std::string& why) {
  std::fprintf(stderr,
               "sl_dds_bench: %s\n"
               "usage: sl_dds_bench sub [--topic T] [--count N] [--timeout S] [--quiet S]\n"
               "       sl_dds_bench pub [--topic T] [--count N] [--rate HZ] [--width W] "
               "[--height H]\n"
               "       sl_dds_bench listen [--topic T] [--duration S] [--timeout S] [--depth N] "
               "[--best-effort 1] [--prefault-clouds N] [--in-place 1]\n",
               why.c_str());
  std::exit(2);
}

Args parse(int argc, char** argv) {
  if (argc < 2) usage("missing mode");
  Args a;
  a.mode = argv[1];
  if (a.mode != "pub" && a.mode != "sub" && a.mode != "listen")
    usage("mode must be pub, sub or listen");
  if (a.mode == "listen") a.timeout_s = 60;
  for (int i = 2; i < argc; ++i) {
    const std::string opt = argv[i];
    if (i + 1 >= argc) usage(opt + " needs a value");
    const char* v = argv[++i];
    char* end = nullptr;
    double number = std::strtod(v, &end);
    if (opt == "--topic") {
      a.topic = v;
      continue;
    }
    if (*end != '\0' || number < 0) usage(opt + ": expected a number >= 0");
    if (opt == "--count" && number >= 1)
      a.count = static_cast<long>(number);
    else if (opt == "--rate")
      a.rate_hz = number;
    else if (opt == "--width" && number >= 1)
      a.width = static_cast<std::uint32_t>(number);
    else if (opt == "--height" && number >= 1)
      a.height = static_cast<std::uint32_t>(number);
    else if (opt == "--timeout" && number > 0)
      a.timeout_s = number;
    else if (opt == "--quiet" && number > 0)
      a.quiet_s = number;
    else if (opt == "--duration" && number > 0)
      a.duration_s = number;
    else if (opt == "--depth" && number >= 1)
      a.depth = static_cast<int>(number);
    else if (opt == "--best-effort")
      a.best_effort = number != 0;
    else if (opt == "--in-place")
      a.in_place = number != 0;
    else if (opt == "--prefault-clouds" && number <= 64)
      a.prefault_clouds = static_cast<long>(number);
    else
      usage("bad option or value: " + opt + " " + v);
  }
  return a;
}

std::int64_t realtimeNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Daemon's cloud writer QoS (daemon/src/dds_bridge.cpp).
dds::Qos writerQos() { return dds::Qos().reliable(DDS_MSECS(200)).keepLast(4).xcdr1(); }
// slctl's cloud reader QoS (client/src/client.cpp).
dds::Qos readerQos() { return dds::Qos().reliable().keepLast(8); }

int publish(const Args& a) {
  dds::Participant participant;
  dds::Topic<Cloud> topic(participant, a.topic, sensor_msgs_msg_dds__PointCloud2__desc);
  dds::Writer<Cloud> writer(participant, topic, writerQos());
  if (!writer.waitForReaders(1, DDS_SECS(10))) {
    std::fprintf(stderr, "sl_dds_bench pub: no subscriber on %s within 10 s\n", a.topic.c_str());
    return 1;
  }
  // A plausible cloud: a tilted plane, NaN in a stripe (the contents do not
  // matter to DDS, the size does).
  const std::size_t points = static_cast<std::size_t>(a.width) * a.height;
  std::vector<float> data(4 * points);
  for (std::uint32_t r = 0; r < a.height; ++r)
    for (std::uint32_t c = 0; c < a.width; ++c) {
      float* p = &data[4 * (static_cast<std::size_t>(r) * a.width + c)];
      p[0] = (c - a.width / 2.0f) * 4e-4f;
      p[1] = (r - a.height / 2.0f) * 4e-4f;
      p[2] = c % 97 == 0 ? std::numeric_limits<float>::quiet_NaN() : 0.55f + r * 1e-4f;
      p[3] = static_cast<float>((r + c) % 256);
    }
  static char kNames[4][10] = {"x", "y", "z", "intensity"};
  Field fields[4];
  for (int i = 0; i < 4; ++i) fields[i] = {kNames[i], static_cast<std::uint32_t>(4 * i), 7, 1};
  static char frame_id[] = "sl_bench";
  Cloud msg{};
  msg.header.frame_id = frame_id;
  msg.height = a.height;
  msg.width = a.width;
  msg.fields = {4, 4, fields, false};
  msg.is_bigendian = false;
  msg.point_step = 16;
  msg.row_step = 16 * a.width;
  msg.data = {static_cast<std::uint32_t>(data.size() * 4),
              static_cast<std::uint32_t>(data.size() * 4),
              reinterpret_cast<std::uint8_t*>(data.data()), false};
  msg.is_dense = false;

  const auto period = a.rate_hz > 0 ? std::chrono::duration<double>(1.0 / a.rate_hz)
                                    : std::chrono::duration<double>(0);
  const auto start = std::chrono::steady_clock::now();
  long not_sent = 0;
  for (long seq = 0; seq < a.count; ++seq) {
    std::this_thread::sleep_until(start + std::chrono::duration_cast<std::chrono::nanoseconds>(
                                              period * static_cast<double>(seq)));
    const std::uint64_t s = static_cast<std::uint64_t>(seq);
    std::memcpy(msg.data._buffer, &s, sizeof s);
    const std::int64_t now = realtimeNs();
    msg.header.stamp.sec = static_cast<std::int32_t>(now / 1000000000);
    msg.header.stamp.nanosec = static_cast<std::uint32_t>(now % 1000000000);
    if (!writer.write(msg)) ++not_sent;
  }
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // Let the reliable protocol finish before the writer goes away.
  dds_wait_for_acks(writer.handle(), DDS_SECS(5));
  std::printf(
      "pub: %ld clouds of %u x %u x 16 B (%.1f MB) in %.2f s (%.2f/s offered), "
      "%ld not sent (write blocked > 200 ms)\n",
      a.count, a.width, a.height, data.size() * 4 / 1e6, elapsed,
      elapsed > 0 ? a.count / elapsed : 0.0, not_sent);
  // The repair traffic behind those figures: bytes the writer sent again
  // for NACKs, and how often and how long it waited for acknowledgements.
  if (dds_statistics* stats = dds_create_statistics(writer.handle())) {
    dds_refresh_statistics(stats);
    auto value = [stats](const char* name) -> std::uint64_t {
      const dds_stat_keyvalue* kv = dds_lookup_statistic(stats, name);
      if (!kv) return 0;
      return kv->kind == DDS_STAT_KIND_UINT32 ? kv->u.u32 : kv->u.u64;
    };
    std::printf("pub: retransmitted %.1f MB (%.1f%% of the data), throttled %" PRIu64
                " times for %.1f ms in all, %.1f ms retransmitting\n",
                value("rexmit_bytes") / 1e6,
                100.0 * value("rexmit_bytes") / (static_cast<double>(a.count) * data.size() * 4),
                value("throttle_count"), value("time_throttle") / 1e6, value("time_rexmit") / 1e6);
    dds_delete_statistics(stats);
  }
  return 0;
}

int subscribe(const Args& a) {
  dds::Participant participant;
  dds::Topic<Cloud> topic(participant, a.topic, sensor_msgs_msg_dds__PointCloud2__desc);
  dds::Reader<Cloud> reader(participant, topic, readerQos());
  dds::ReadCondition has_data(reader);
  dds::WaitSet waitset(participant);
  waitset.attach(has_data);
  std::printf("sub: waiting on %s\n", a.topic.c_str());
  std::fflush(stdout);

  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(a.timeout_s);
  std::vector<double> latency_ms;
  std::vector<bool> seen(static_cast<std::size_t>(a.count), false);
  long received = 0, bad = 0;
  std::int64_t first_rx = 0, last_rx = 0;
  auto last_sample = std::chrono::steady_clock::now();
  bool got_last = false;
  while (!got_last && std::chrono::steady_clock::now() < deadline) {
    if (received > 0 &&
        std::chrono::steady_clock::now() - last_sample > std::chrono::duration<double>(a.quiet_s))
      break;
    if (!waitset.wait(DDS_MSECS(200))) continue;
    dds::Loan<Cloud> loan = reader.take(8);
    const std::int64_t rx = realtimeNs();
    for (std::size_t i = 0; i < loan.size(); ++i) {
      if (!loan.isValid(i)) continue;
      const Cloud& c = loan[i];
      std::uint64_t seq = 0;
      if (c.data._length < sizeof seq ||
          c.data._length != static_cast<std::size_t>(c.height) * c.row_step) {
        ++bad;
        continue;
      }
      std::memcpy(&seq, c.data._buffer, sizeof seq);
      if (seq >= seen.size()) {
        ++bad;
        continue;
      }
      seen[seq] = true;
      ++received;
      const std::int64_t stamp =
          static_cast<std::int64_t>(c.header.stamp.sec) * 1000000000 + c.header.stamp.nanosec;
      latency_ms.push_back((rx - stamp) * 1e-6);
      if (first_rx == 0) first_rx = rx;
      last_rx = rx;
      got_last = got_last || seq + 1 == seen.size();
    }
    last_sample = std::chrono::steady_clock::now();
  }
  const long lost = a.count - received;
  std::sort(latency_ms.begin(), latency_ms.end());
  auto quantile = [&](double q) {
    if (latency_ms.empty()) return 0.0;
    const std::size_t i = std::min(latency_ms.size() - 1,
                                   static_cast<std::size_t>(q * (latency_ms.size() - 1) + 0.5));
    return latency_ms[i];
  };
  const double span_s = (last_rx - first_rx) * 1e-9;
  std::printf(
      "sub: received %ld of %ld clouds (lost %ld = %.1f %%, malformed %ld), "
      "%.2f clouds/s delivered, latency median %.1f ms p99 %.1f ms max %.1f ms\n",
      received, a.count, lost, 100.0 * lost / a.count, bad,
      received > 1 && span_s > 0 ? (received - 1) / span_s : 0.0, quantile(0.5), quantile(0.99),
      latency_ms.empty() ? 0.0 : latency_ms.back());
  return received > 0 ? 0 : 1;
}

// The header stamp of a cloud taken serialized, its layout checked (the
// data holds width x height points) without copying the points; -1 for a
// sample without data (a writer gone) or a malformed one (counted).
std::int64_t inPlaceStamp(ddsi_serdata* serdata, const dds_sample_info_t& info, long& malformed) {
  if (!info.valid_data) return -1;
  const std::uint32_t size = ddsi_serdata_size(serdata);
  ddsrt_iovec_t iov;
  ddsi_serdata* ref = ddsi_serdata_to_ser_ref(serdata, 0, size, &iov);
  std::int64_t stamp = -1;
  try {
    if (ref == nullptr || iov.iov_len != size) throw sl::tools::CdrError("not contiguous");
    stamp = sl::tools::parsePointCloud2(static_cast<const std::uint8_t*>(iov.iov_base), size).stampNs();
  } catch (const sl::tools::CdrError& e) {
    if (malformed++ == 0) std::fprintf(stderr, "listen: %s\n", e.what());
  }
  if (ref != nullptr) ddsi_serdata_to_ser_unref(ref, &iov);
  return stamp;
}

int listen(const Args& a) {
  dds::Participant participant;
  dds::Topic<Cloud> topic(participant, a.topic, sensor_msgs_msg_dds__PointCloud2__desc);
  dds::Qos qos;
  if (a.best_effort)
    qos.bestEffort();
  else
    qos.reliable();
  qos.keepLast(a.depth);
  dds::Reader<Cloud> reader(participant, topic, qos);
  // As the daemon does (no-op without shared memory).
  if (const std::size_t shm = sl::dds::populateSharedMemoryMappings())
    std::fprintf(stderr, "listen: page tables of %zu MiB of shared memory filled in\n", shm >> 20);
  // Samples are deserialized into memory of the thread that takes them.
  sl::dds::prefaultHeap(std::size_t{1440} * 1080 * 16 + 4096, static_cast<std::size_t>(a.prefault_clouds));
  dds::ReadCondition has_data(reader);
  dds::WaitSet waitset(participant);
  waitset.attach(has_data);
  using Clock = std::chrono::steady_clock;
  const Clock::time_point give_up =
      Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(a.timeout_s));
  Clock::time_point end = Clock::time_point::max();
  long received = 0;
  // Per cloud: stamp, take time, the writer's source timestamp (when the
  // daemon called dds_write) and the minor page faults of its take.
  struct Rx {
    std::int64_t stamp, take, written, before;
    long faults;
  };
  std::vector<Rx> rx;
  rx.reserve(4096);
  long malformed = 0;
  auto minorFaults = [] {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return usage.ru_minflt;
  };
  while (Clock::now() < (received == 0 ? give_up : end)) {
    if (!waitset.wait(DDS_MSECS(100))) continue;
    for (;;) {
      const long faults_before = minorFaults();
      const std::int64_t before = realtimeNs();
      if (a.in_place) {
        // As sl_view reads clouds: the serialized sample, parsed in place.
        struct ddsi_serdata* serdata = nullptr;
        dds_sample_info_t info;
        if (dds::check(dds_takecdr(reader.handle(), &serdata, 1, &info, DDS_ANY_STATE), "dds_takecdr") <= 0)
          break;
        const std::int64_t stamp = inPlaceStamp(serdata, info, malformed);
        const std::int64_t now = realtimeNs();
        ddsi_serdata_unref(serdata);
        if (stamp < 0) continue;
        rx.push_back({stamp, now, info.source_timestamp, before, minorFaults() - faults_before});
        if (received++ == 0)
          end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>(a.duration_s));
        continue;
      }
      dds::Loan<Cloud> loan = reader.take(8);
      if (loan.empty()) break;
      const std::int64_t now = realtimeNs();
      const long faults = minorFaults() - faults_before;
      for (std::size_t i = 0; i < loan.size(); ++i) {
        if (!loan.isValid(i)) continue;
        const Cloud& c = loan[i];
        rx.push_back({static_cast<std::int64_t>(c.header.stamp.sec) * 1000000000 + c.header.stamp.nanosec,
                      now, loan.info(i).source_timestamp, before, faults});
        if (received++ == 0)
          end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>(a.duration_s));
      }
    }
  }
  for (const Rx& r : rx)
    std::printf("rx %" PRId64 " %" PRId64 " %" PRId64 " %ld %" PRId64 "\n", r.stamp, r.take, r.written, r.faults, r.before);
  // Page faults are what a reader's fresh 25 MB buffers cost (README, DDS
  // deployment): printed so that the benchmark can report them per cloud.
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  std::printf("listen: done %ld, minor page faults %ld, malformed %ld\n", received, usage.ru_minflt, malformed);
  return received > 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parse(argc, argv);
  sl::dds::retainLargeSampleMemory();  // as the daemon and its tools do
  try {
    if (args.mode == "listen") return listen(args);
    return args.mode == "pub" ? publish(args) : subscribe(args);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sl_dds_bench %s: %s\n", args.mode.c_str(), e.what());
    return 2;
  }
}
