#include "mcap_record.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <cstdio>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <thread>
#include <utility>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/cdr.h"
#include "common/mcap_writer.h"
#include "common/ros2_schemas.h"
#include "options.h"
#include "raw_topics.h"
#include "sl/client/client.h"

namespace sl::view {

namespace {

// A scan: its cloud's header stamp (ns) and frame, shared by the scan's
// depth and shading images and camera_info.
using ScanKey = std::pair<std::uint64_t, std::string>;

// Topics with one message per scan, stamped as the scan's cloud. An image
// set's stamp is the cloud's (the sequence's trigger time), its frame_id
// empty; the daemon publishes it after the cloud, so a recording that ends
// with the N-th cloud waits for it as for the images.
bool isScanTopic(const std::string& type_name) {
  return type_name == "sensor_msgs/msg/PointCloud2" || type_name == "sensor_msgs/msg/Image" ||
         type_name == "sensor_msgs/msg/CameraInfo" || type_name == "sl_msgs/msg/ImageSet";
}

// Whether topic t holds scan k's message among the keys `held`.
bool holds(const TopicInfo& t, const std::set<ScanKey>& held, const ScanKey& k) {
  if (t.type_name == "sl_msgs/msg/ImageSet") return held.count({k.first, ""}) > 0;
  return held.count(k) > 0;
}

ScanKey scanKey(const RawSample& s, const std::string& topic) {
  tools::CdrReader header(s.data(), s.size(), topic + " sample");
  const std::int32_t sec = header.i32();
  const std::uint32_t nanosec = header.u32();
  return {static_cast<std::uint64_t>(sec) * 1000000000ull + nanosec, header.string()};
}

// Whether topic t should hold a message of scan k, given the keys it holds:
// camera_info describes the first camera only (the frame of the camera_info
// messages seen; every frame if none was seen).
bool expects(const TopicInfo& t, const std::set<ScanKey>& held, const ScanKey& k) {
  if (t.type_name != "sensor_msgs/msg/CameraInfo" || held.empty()) return true;
  for (const auto& h : held)
    if (h.second == k.second) return true;
  return false;
}

// Samples on their way into the file. The DDS side only takes samples and
// queues them; this queue's thread compresses and writes, so a slow disk or
// a CPU-starved compressor never leaves a DDS reader's keep-last history to
// overwrite samples unseen. Bounded by bytes: a sample that does not fit is
// dropped and counted. Thread-safe.
class WriteQueue {
 public:
  WriteQueue(tools::McapWriter& writer, std::size_t max_bytes)
      : writer_(writer), max_bytes_(max_bytes), thread_([this] { run(); }) {}
  ~WriteQueue() { finish(); }

  // False (and counted) if the queue is full or the writer failed.
  bool push(std::uint16_t channel, std::uint32_t sequence, std::shared_ptr<const RawSample> s) {
    std::lock_guard<std::mutex> lock(mu_);
    if (error_ || bytes_ + s->size() > max_bytes_) {
      ++dropped_;
      return false;
    }
    bytes_ += s->size();
    queue_.push_back({channel, sequence, std::move(s)});
    cv_.notify_one();
    return true;
  }
  // Writes what is queued, stops the thread; rethrows a write error.
  void finish() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
      cv_.notify_one();
    }
    if (thread_.joinable()) thread_.join();
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }
  bool failed() const {
    std::lock_guard<std::mutex> lock(mu_);
    return error_ != nullptr;
  }
  std::uint64_t dropped() const {
    std::lock_guard<std::mutex> lock(mu_);
    return dropped_;
  }

 private:
  struct Item {
    std::uint16_t channel;
    std::uint32_t sequence;
    std::shared_ptr<const RawSample> sample;
  };
  void run() {
    for (;;) {
      Item item;
      {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [&] { return done_ || !queue_.empty(); });
        if (queue_.empty()) return;
        item = std::move(queue_.front());
        queue_.pop_front();
      }
      try {
        writer_.write(item.channel, item.sequence, item.sample->receive_ns, item.sample->source_ns,
                      item.sample->bytes());
      } catch (...) {
        std::lock_guard<std::mutex> lock(mu_);
        error_ = std::current_exception();
        dropped_ += queue_.size() + 1;
        queue_.clear();
        bytes_ = 0;
        return;
      }
      std::lock_guard<std::mutex> lock(mu_);
      bytes_ -= item.sample->size();
    }
  }

  tools::McapWriter& writer_;  // used by the thread only
  const std::size_t max_bytes_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Item> queue_;       // guarded by mu_
  std::size_t bytes_ = 0;        // guarded by mu_
  std::uint64_t dropped_ = 0;    // guarded by mu_
  bool done_ = false;            // guarded by mu_
  std::exception_ptr error_;     // guarded by mu_
  std::thread thread_;
};

}  // namespace

int recordMain(int argc, char** argv, const std::atomic<bool>& stop) {
  if (argc < 2 || argv[1][0] == '-')
    throw std::invalid_argument("record needs the output file (sl_view record FILE.mcap)");
  const std::string path = argv[1];
  RawTopicsOptions topics;
  // A recording wants every sample: reliable (repaired), room for a burst
  // while a chunk is compressed.
  topics.best_effort = false;
  topics.depth = 8;
  tools::McapWriterOptions mcap;
  long count = 0, scan = -1;  // scan: -1 none, 0 continuous
  double seconds = 0;
  std::size_t buffer_mb = 1024;  // samples taken but not yet written
  for (ArgCursor args(argc, argv, 2); args.next();) {
    const std::string a = args.option();
    if (parseTopicOption(args, topics)) continue;
    if (a == "--topics") {
      std::stringstream list(args.value());
      for (std::string t; std::getline(list, t, ',');)
        if (!t.empty()) topics.only.push_back(t);
    } else if (a == "--count") count = args.integer(1, 1000000);
    else if (a == "--scan") scan = args.integer(0, 1000000);
    else if (a == "--seconds") seconds = args.positive();
    else if (a == "--buffer-mb") buffer_mb = static_cast<std::size_t>(args.integer(64, 65536));
    else if (a == "--compression") {
      mcap.compression = args.value();
      if (mcap.compression == "none") mcap.compression.clear();
      if (mcap.compression != "" && mcap.compression != "zstd" && mcap.compression != "lz4")
        throw std::invalid_argument("--compression " + mcap.compression + ": zstd, lz4 or none");
    } else throw std::invalid_argument("record: unknown option '" + a + "'");
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
  std::optional<client::SensorClient> client;
  if (scan >= 0) {
    client.emplace(clientOptions(topics));
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
    // Our readers see the daemon's writers; the writers learn of our readers
    // by a separate discovery message, which can lag on a loaded machine (a
    // scan published before misses this file, and is named at the end).
    // Give it as long again as finding the daemon took, 0.5 to 3 s.
    std::this_thread::sleep_for(std::clamp<std::chrono::steady_clock::duration>(
        std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(500), std::chrono::seconds(3)));
    for (std::size_t i = 0; i < raw.topics().size(); ++i) {
      std::int32_t policy = 0;
      if (raw.matchedWriters(i) == 0 && raw.incompatibleWriters(i, &policy) > 0)
        throw std::runtime_error(raw.topics()[i].ros_name +
                                 ": the daemon's writer QoS does not match this reader (policy id " +
                                 std::to_string(policy) + ")");
    }
    const auto reply = client->request(client::Command::kStart, "", static_cast<int>(scan),
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

  // A scan's cloud, depth and shading images and camera_info share the
  // cloud's header stamp and frame (its image set the stamp), and the daemon
  // publishes them after the cloud: a recording that ends (the N-th cloud, --seconds,
  // Ctrl-C, the daemon idle) waits up to kTailWait for the latest recorded
  // cloud's other messages, and leaves out the next scan's. At the end, each
  // scan topic is checked against the clouds: a message missing is named and
  // makes the exit code 5.
  std::vector<std::size_t> scan_topics;  // topics other than the cloud carrying one per scan
  for (std::size_t i = 0; i < raw.topics().size(); ++i)
    if (i != points_topic && isScanTopic(raw.topics()[i].type_name)) scan_topics.push_back(i);
  std::set<ScanKey> cloud_keys;
  std::vector<std::set<ScanKey>> keys_of(raw.topics().size());
  std::optional<ScanKey> last_cloud;  // the N-th cloud, once recorded
  std::optional<std::chrono::steady_clock::time_point> tail_since;
  constexpr auto kTailWait = std::chrono::seconds(3);
  const auto tailComplete = [&] {
    for (const std::size_t i : scan_topics)
      if (!holds(raw.topics()[i], keys_of[i], *last_cloud) &&
          expects(raw.topics()[i], keys_of[i], *last_cloud))
        return false;
    return true;
  };

  std::vector<std::uint32_t> sequence(raw.topics().size(), 0);
  long clouds = 0;
  std::uint64_t bytes = 0;
  std::uint64_t dropped_after = 0;  // samples of scans after the last one recorded
  // Images, camera_info and image sets are written once their scan's cloud
  // is: one taken before its cloud (a 25 MB cloud can arrive after its
  // scan's small images) is held until the cloud comes. Held ones whose
  // cloud is overtaken by a later one never get it (the daemon's keep-last
  // writer dropped it for a recorder that fell behind, or matched the cloud
  // reader late): they are left out, and counted once the recording has its
  // first cloud, so every scan in the file is whole.
  std::map<std::uint64_t, std::vector<std::pair<ScanKey, std::shared_ptr<const RawSample>>>>
      awaiting_cloud;  // by stamp
  std::set<std::uint64_t> cloud_stamps;
  std::size_t scans_without_cloud = 0;
  // With --scan: the daemon going back to idle ends the recording too (a
  // scan it could not complete never comes); 0.5 s later, for the last
  // images.
  bool scanning_seen = false;
  std::optional<std::uint64_t> writes_timed_out_at_start, writes_timed_out;
  std::optional<std::chrono::steady_clock::time_point> idle_since;
  WriteQueue queue(writer, buffer_mb << 20);
  std::vector<std::uint64_t> not_written(raw.topics().size(), 0);
  // Writes a sample (false if the queue refused it).
  const auto record = [&](const std::shared_ptr<const RawSample>& s, const std::optional<ScanKey>& key) {
    const std::size_t size = s->size();
    if (!queue.push(channel_of[s->topic], sequence[s->topic] + 1, s)) {
      ++not_written[s->topic];
      return false;
    }
    ++sequence[s->topic];
    bytes += size;
    if (key) keys_of[s->topic].insert(*key);
    return true;
  };
  // A sample taken: written, or left out (the next scan's, or held until
  // the first cloud).
  const std::function<void(std::shared_ptr<const RawSample>)> handle =
      [&](std::shared_ptr<const RawSample> s) {
    const TopicInfo& t = raw.topics()[s->topic];
    std::optional<ScanKey> key;
    if (s->topic == points_topic || isScanTopic(t.type_name)) key = scanKey(*s, t.dds_name);
    if (last_cloud && key && *key > *last_cloud) {
      ++dropped_after;  // the next scan's: not part of this recording
      return;
    }
    if (key && s->topic != points_topic && !cloud_stamps.count(key->first)) {
      awaiting_cloud[key->first].emplace_back(*key, s);
      return;
    }
    if (!record(s, key)) return;
    if (s->topic == points_topic) {
      const bool first = cloud_stamps.empty();
      cloud_keys.insert(*key);
      cloud_stamps.insert(key->first);
      if (count > 0 && ++clouds >= count) last_cloud = key;
      else if (count == 0) ++clouds;
      for (auto it = awaiting_cloud.begin(); it != awaiting_cloud.end() && it->first <= key->first;) {
        if (it->first == key->first) {
          for (const auto& [held_key, held] : it->second) record(held, held_key);
        } else if (!first) {
          ++scans_without_cloud;
        }
        it = awaiting_cloud.erase(it);
      }
    }
    if (s->topic == status_topic) {
      tools::CdrReader status(s->data(), s->size(), "status sample");
      status.i32();  // stamp
      status.u32();
      const std::uint32_t state = status.u32();  // sl_msgs State: 0 idle, 1 scanning
      status.string();                           // pattern
      status.u64();                              // scans_done
      status.u64();                              // scans_requested
      status.f64();                              // scan_rate_hz
      for (int k = 0; k < 6; ++k) status.u64();  // frames_dropped .. sets_overflow
      writes_timed_out = status.u64();
      if (!writes_timed_out_at_start) writes_timed_out_at_start = writes_timed_out;
      if (scan > 0) {
        if (state == 1 || state == 3 || state == 4) scanning_seen = true;
        if (state == 0 && scanning_seen && !idle_since) idle_since = std::chrono::steady_clock::now();
      }
    }
  };

  // Warm-up (--scan 0, i.e. scanning continuously, with topics besides the
  // cloud): the daemon's writers
  // learn of this recorder's readers each by its own discovery message, and
  // under load one can lag the scan request, so that the first scan lacks
  // its images (or its cloud). Samples are held, by scan, until a scan is
  // whole; the scans before it are left out and not counted. After
  // kWarmupScans clouds without a whole scan, everything held is written
  // as it came and a missing message is named at the end as before.
  bool warming = scan == 0 && !scan_topics.empty();
  constexpr std::size_t kWarmupScans = 2;
  std::map<std::uint64_t, std::vector<std::shared_ptr<const RawSample>>> warmup;  // by stamp
  std::size_t warmup_left_out = 0;  // scans with a cloud
  const auto endWarmUp = [&](std::uint64_t first_stamp) {
    warming = false;
    for (auto& [stamp, samples] : warmup) {
      if (stamp < first_stamp) {
        warmup_left_out += std::any_of(samples.begin(), samples.end(),
                                       [&](const auto& x) { return x->topic == points_topic; });
        continue;
      }
      std::stable_partition(samples.begin(), samples.end(),
                            [&](const auto& x) { return x->topic == points_topic; });
      for (auto& x : samples) handle(std::move(x));
    }
    warmup.clear();
  };
  const auto warmUp = [&](std::shared_ptr<const RawSample> s) {
    const TopicInfo& t = raw.topics()[s->topic];
    if (s->topic != points_topic && !isScanTopic(t.type_name)) return handle(std::move(s));
    warmup[scanKey(*s, t.dds_name).first].push_back(std::move(s));
    std::size_t clouds_held = 0;
    for (const auto& [stamp, samples] : warmup) {
      std::set<std::size_t> present;
      for (const auto& x : samples) present.insert(x->topic);
      if (!present.count(points_topic)) continue;
      ++clouds_held;
      if (std::all_of(scan_topics.begin(), scan_topics.end(),
                      [&](std::size_t i) { return present.count(i) > 0; }))
        return endWarmUp(stamp);
    }
    if (clouds_held > kWarmupScans) endWarmUp(0);
  };

  while (!queue.failed()) {
    const auto now = std::chrono::steady_clock::now();
    if (last_cloud) {
      if (tailComplete()) break;
      if (!tail_since) tail_since = now;
      if (now - *tail_since > kTailWait) break;
    } else {
      // Ctrl-C, --seconds, or the daemon idle before --scan N was done: the
      // recording still ends with the latest cloud's scan complete.
      bool end = stop || (seconds > 0 && std::chrono::duration<double>(now - t0).count() >= seconds);
      if (idle_since && now - *idle_since > std::chrono::milliseconds(500)) {
        std::cerr << "sl_view record: the daemon went idle after " << clouds << " of " << count
                  << " clouds\n";
        end = true;
      }
      if (end && warming) endWarmUp(0);
      if (end) {
        if (cloud_keys.empty()) break;
        last_cloud = *cloud_keys.rbegin();
      }
    }
    raw.poll(DDS_MSECS(100), [&](std::shared_ptr<const RawSample> s) {
      if (warming) warmUp(std::move(s));
      else handle(std::move(s));
    });
  }
  if (scan == 0) {
    const auto reply = client->request(client::Command::kStop, "", 0, std::chrono::seconds(10));
    if (!reply || !reply->accepted)
      std::cerr << "sl_view record: could not stop the scan: "
                << (reply ? reply->reason : std::string("no reply")) << "\n";
  }
  queue.finish();
  writer.close();
  if (!cloud_stamps.empty())
    for (const auto& [stamp, held] : awaiting_cloud) scans_without_cloud += stamp < *cloud_stamps.rbegin();
  if (scans_without_cloud > 0)
    std::printf("sl_view record: %zu scan(s) left out: their cloud did not reach the recorder (the "
                "daemon's writer dropped it for this reader, behind or late)\n",
                scans_without_cloud);
  if (warmup_left_out > 0)
    std::printf("sl_view record: %zu scan(s) at the start left out: a message missing (a daemon "
                "writer had not yet discovered this recorder)\n",
                warmup_left_out);
  std::printf("sl_view record: %llu messages (%ld clouds, %.1f MB of CDR) -> %s\n",
              static_cast<unsigned long long>(writer.messageCount()), clouds, bytes / 1e6,
              path.c_str());
  int rc = 0;
  for (std::size_t i = 0; i < raw.topics().size(); ++i) {
    if (not_written[i] == 0) continue;
    std::fprintf(stderr,
                 "sl_view record: %s: %llu samples dropped: the file writer fell %d MB behind "
                 "(--buffer-mb)\n",
                 raw.topics()[i].ros_name.c_str(), static_cast<unsigned long long>(not_written[i]),
                 static_cast<int>(buffer_mb));
    rc = 5;
  }
  // Every scan topic against the clouds recorded.
  for (const std::size_t i : scan_topics) {
    std::size_t missing = 0;
    for (const auto& k : cloud_keys)
      if (!holds(raw.topics()[i], keys_of[i], k) && expects(raw.topics()[i], keys_of[i], k)) ++missing;
    if (missing == 0) continue;
    std::fprintf(stderr, "sl_view record: %s: %zu of the %zu scans recorded have no message\n",
                 raw.topics()[i].ros_name.c_str(), missing, cloud_keys.size());
    rc = 5;
  }
  if (rc != 0 && writes_timed_out && *writes_timed_out > *writes_timed_out_at_start)
    std::fprintf(stderr,
                 "sl_view record: the daemon counted %llu DDS writes timed out meanwhile "
                 "(writes_timed_out): it did not publish them\n",
                 static_cast<unsigned long long>(*writes_timed_out - *writes_timed_out_at_start));
  return rc;
}

}  // namespace sl::view
