// The daemon's DDS topics read as serialized samples: each sample's CDR bytes
// exactly as the daemon's writer produced them (4-byte encapsulation header
// first), without deserializing them. Used by sl_view (forwarded to
// Foxglove clients) and by its MCAP recorder (written to the file).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "sl/dds/dds.h"

namespace sl::view {

// A daemon topic: DDS name, ROS 2 name (as Foxglove and rosbag2 show it) and
// ROS 2 type.
struct TopicInfo {
  std::string dds_name;   // "rt/sl/points"
  std::string ros_name;   // "/sl/points"
  std::string type_name;  // "sensor_msgs/msg/PointCloud2"
};

// The topics the daemon publishes (sl::dds::TopicNames) for namespace ns.
std::vector<TopicInfo> daemonTopics(const std::string& ns);

// One received sample, holding a reference on Cyclone's serialized data (no
// copy). Immutable; share it between consumers with shared_ptr.
class RawSample {
 public:
  RawSample(const RawSample&) = delete;
  RawSample& operator=(const RawSample&) = delete;
  ~RawSample();

  std::string_view bytes() const { return bytes_; }
  const std::uint8_t* data() const { return reinterpret_cast<const std::uint8_t*>(bytes_.data()); }
  std::size_t size() const { return bytes_.size(); }
  std::size_t topic = 0;             // index into RawTopics::topics()
  std::uint64_t receive_ns = 0;      // wall clock when taken
  std::uint64_t source_ns = 0;       // the writer's source timestamp
  std::uint64_t sequence = 0;        // per RawTopics, increasing

 private:
  friend class RawTopics;
  RawSample() = default;
  struct ddsi_serdata* serdata_ = nullptr;  // the reference taken from the reader
  struct ddsi_serdata* ref_ = nullptr;      // from ddsi_serdata_to_ser_ref, or null
  void* iov_base_ = nullptr;
  std::size_t iov_len_ = 0;
  std::string copy_;  // only if Cyclone's data could not be referenced in one piece
  std::string_view bytes_;
};

struct RawTopicsOptions {
  int domain_id = 0;
  std::string ns = "sl";
  // Clouds and images (status is always reliable + transient-local, so the
  // latest one arrives on start-up):
  // - reliable, keep-last `depth` (default; the live view with depth 1, the
  //   recorder with 8): lost fragments are repaired, so a 25 MB cloud
  //   arrives whatever the socket receive buffer. A reader that stops (a
  //   stopped or CPU-starved sl_view) does not block the daemon: its
  //   writers' keep-last histories drop the oldest unacknowledged cloud for
  //   that reader only (view_starved: no DDS write timed out, the scan rate
  //   held). What it costs the daemon is the repairs it sends.
  // - best-effort, keep-last `depth` (--best-effort): never repaired nor
  //   waited for; a cloud is lost when one fragment is, i.e. when its burst
  //   overflows the socket receive buffer (Linux grants at most
  //   net.core.rmem_max: with 4 MiB, no 25 MB cloud and a third of the
  //   clouds read for the 1.6 MB preview were lost at load 14, README).
  // Clouds missed either way are counted by sl_view (GET /stats "dds").
  bool best_effort = false;
  int depth = 1;  // keep-last depth of the cloud and image readers
  std::vector<std::string> only;  // ROS names to subscribe; empty = all
  // Lazy: only the status reader exists at first; setActive() creates and
  // deletes the others (sl_view reads a topic only while a viewer wants it).
  bool lazy = false;
};

// Not thread-safe except wake(), which any thread may call.
class RawTopics {
 public:
  using Callback = std::function<void(std::shared_ptr<const RawSample>)>;
  explicit RawTopics(const RawTopicsOptions& options);
  ~RawTopics();

  const std::vector<TopicInfo>& topics() const;
  // Waits up to timeout_ns for samples and hands each to `callback` (on this
  // thread). Returns false if woken by wake().
  bool poll(std::int64_t timeout_ns, const Callback& callback);
  void wake();
  // Creates (true) or deletes (false) topic i's reader; status stays.
  void setActive(std::size_t i, bool active);
  bool active(std::size_t i) const;
  // Writers matched on topic i (0 until discovery or while inactive).
  std::uint32_t matchedWriters(std::size_t i) const;
  // Samples Cyclone reported lost (best-effort fragments missing) per topic,
  // by the current reader (0 while inactive).
  std::uint64_t samplesLost(std::size_t i) const;
  // Samples Cyclone rejected for want of room in the reader's history (its
  // sample-rejected status; 0 while inactive).
  std::uint64_t samplesRejected(std::size_t i) const;
  // Writers on topic i that did not match for incompatible QoS (0 while
  // inactive), and the last policy that did not match (DDS_*_QOS_POLICY_ID).
  std::uint32_t incompatibleWriters(std::size_t i, std::int32_t* last_policy = nullptr) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::view
