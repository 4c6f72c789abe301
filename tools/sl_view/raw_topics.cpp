#include "raw_topics.h"

#include <dds/ddsi/ddsi_serdata.h>

#include <algorithm>
#include <chrono>
#include <optional>
#include <stdexcept>

#include "builtin_interfaces/msg/Time.h"
#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/dds/topic_names.h"
#include "sl_msgs/msg/ImageSet.h"
#include "sl_msgs/msg/ProjectorMaps.h"
#include "sl_msgs/msg/Status.h"

namespace sl::view {

namespace {

// dds::Topic / dds::Reader need a sample type only for take(), which is not
// used here (dds_takecdr reads the serialized form).
struct Serialized {};

std::string rosName(const std::string& dds_name) {
  // "rt/sl/points" -> "/sl/points"
  if (dds_name.rfind("rt/", 0) != 0)
    throw std::invalid_argument("topic '" + dds_name + "' has no ROS 2 'rt/' prefix");
  return dds_name.substr(2);
}

const dds_topic_descriptor_t& descriptorOf(const std::string& type_name) {
  if (type_name == "sensor_msgs/msg/PointCloud2") return sensor_msgs_msg_dds__PointCloud2__desc;
  if (type_name == "sensor_msgs/msg/Image") return sensor_msgs_msg_dds__Image__desc;
  if (type_name == "sensor_msgs/msg/CameraInfo") return sensor_msgs_msg_dds__CameraInfo__desc;
  if (type_name == "sl_msgs/msg/Status") return sl_msgs_msg_dds__Status__desc;
  if (type_name == "sl_msgs/msg/ImageSet") return sl_msgs_msg_dds__ImageSet__desc;
  if (type_name == "sl_msgs/msg/ProjectorMaps") return sl_msgs_msg_dds__ProjectorMaps__desc;
  throw std::invalid_argument("no DDS type for '" + type_name + "'");
}

std::uint64_t nowNs() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
}

}  // namespace

std::vector<TopicInfo> daemonTopics(const std::string& ns) {
  const auto names = dds::TopicNames::forNamespace(ns);
  const auto topic = [](const std::string& dds_name, const char* type) {
    return TopicInfo{dds_name, rosName(dds_name), type};
  };
  return {topic(names.points, "sensor_msgs/msg/PointCloud2"),
          topic(names.depth_image, "sensor_msgs/msg/Image"),
          topic(names.shading_image, "sensor_msgs/msg/Image"),
          topic(names.camera_info, "sensor_msgs/msg/CameraInfo"),
          topic(names.status, "sl_msgs/msg/Status"),
          topic(names.image_sets, "sl_msgs/msg/ImageSet"),
          topic(names.projector_maps, "sl_msgs/msg/ProjectorMaps")};
}

RawSample::~RawSample() {
  if (ref_ != nullptr) {
    ddsrt_iovec_t iov;
    iov.iov_base = iov_base_;
    iov.iov_len = static_cast<decltype(iov.iov_len)>(iov_len_);
    ddsi_serdata_to_ser_unref(ref_, &iov);
  }
  if (serdata_ != nullptr) ddsi_serdata_unref(serdata_);
}

struct RawTopics::Impl {
  explicit Impl(const RawTopicsOptions& opts)
      : options(opts), participant(opts.domain_id), wake(participant), waitset(participant) {
    for (const auto& t : daemonTopics(options.ns)) {
      if (!options.only.empty()) {
        bool wanted = false;
        for (const auto& name : options.only) wanted = wanted || name == t.ros_name;
        if (!wanted) continue;
      }
      infos.push_back(t);
    }
    for (const auto& name : options.only) {
      bool known = false;
      for (const auto& t : infos) known = known || t.ros_name == name;
      if (!known) throw std::invalid_argument("unknown topic '" + name + "' (the daemon's topics are /<ns>/points, /<ns>/status, ...)");
    }
    topics.reserve(infos.size());
    for (const auto& info : infos)
      topics.emplace_back(participant, info.dds_name, descriptorOf(info.type_name));
    readers.resize(infos.size());
    conditions.resize(infos.size());
    for (std::size_t i = 0; i < infos.size(); ++i)
      if (!options.lazy || infos[i].type_name == "sl_msgs/msg/Status") setActive(i, true);
    waitset.attach(wake, 0);
  }

  void setActive(std::size_t i, bool active) {
    if (active == readers[i].has_value()) return;
    if (!active) {
      if (infos[i].type_name == "sl_msgs/msg/Status") return;
      waitset.detach(*conditions[i]);
      conditions[i].reset();
      readers[i].reset();
      return;
    }
    dds::Qos qos;
    if (infos[i].type_name == "sl_msgs/msg/Status")
      qos.reliable().transientLocal().keepLast(1);
    else if (options.best_effort)
      qos.bestEffort().keepLast(options.depth);
    else
      qos.reliable().keepLast(options.depth);
    readers[i].emplace(participant, topics[i], qos);
    conditions[i].emplace(*readers[i]);
    waitset.attach(*conditions[i], static_cast<dds_attach_t>(i + 1));
  }

  RawTopicsOptions options;
  dds::Participant participant;
  std::vector<TopicInfo> infos;
  std::vector<dds::Topic<Serialized>> topics;
  std::vector<std::optional<dds::Reader<Serialized>>> readers;
  std::vector<std::optional<dds::ReadCondition>> conditions;
  dds::GuardCondition wake;
  dds::WaitSet waitset;
  std::uint64_t next_sequence = 1;
};

RawTopics::RawTopics(const RawTopicsOptions& options) : impl_(std::make_unique<Impl>(options)) {}
RawTopics::~RawTopics() = default;

const std::vector<TopicInfo>& RawTopics::topics() const { return impl_->infos; }

bool RawTopics::poll(std::int64_t timeout_ns, const Callback& callback) {
  std::vector<dds_attach_t> triggered;
  impl_->waitset.wait(timeout_ns, &triggered);
  // Every triggered reader is emptied before any callback runs, and the
  // samples are handed over in the order they were taken: a slow callback
  // on one topic's samples (a 25 MB cloud compressed into a file) must not
  // leave the other readers' keep-last histories to overwrite theirs.
  std::vector<std::shared_ptr<RawSample>> batch;
  bool woken = false;
  for (const dds_attach_t cookie : triggered) {
    if (cookie == 0) {
      woken = true;
      impl_->wake.reset();
      continue;
    }
    const std::size_t i = static_cast<std::size_t>(cookie - 1);
    if (!impl_->readers[i]) continue;
    for (;;) {
      struct ddsi_serdata* serdata = nullptr;
      dds_sample_info_t info;
      const dds_return_t n =
          dds::check(dds_takecdr(impl_->readers[i]->handle(), &serdata, 1, &info, DDS_ANY_STATE),
                     "dds_takecdr(" + impl_->infos[i].dds_name + ")");
      if (n <= 0) break;
      std::shared_ptr<RawSample> sample(new RawSample());
      sample->serdata_ = serdata;
      if (!info.valid_data) continue;  // a writer went away: no data
      sample->topic = i;
      sample->receive_ns = nowNs();
      sample->source_ns = static_cast<std::uint64_t>(info.source_timestamp);
      const std::uint32_t size = ddsi_serdata_size(serdata);
      ddsrt_iovec_t iov;
      sample->ref_ = ddsi_serdata_to_ser_ref(serdata, 0, size, &iov);
      if (sample->ref_ != nullptr && iov.iov_len == size) {
        sample->iov_base_ = iov.iov_base;
        sample->iov_len_ = iov.iov_len;
        sample->bytes_ = std::string_view(static_cast<const char*>(iov.iov_base), iov.iov_len);
      } else {
        if (sample->ref_ != nullptr) {
          ddsi_serdata_to_ser_unref(sample->ref_, &iov);
          sample->ref_ = nullptr;
        }
        sample->copy_.resize(size);
        ddsi_serdata_to_ser(serdata, 0, size, sample->copy_.data());
        sample->bytes_ = sample->copy_;
      }
      batch.push_back(std::move(sample));
    }
  }
  // In the writers' order (a scan's cloud before its images), then as taken.
  std::stable_sort(batch.begin(), batch.end(), [](const auto& a, const auto& b) {
    return a->source_ns < b->source_ns;
  });
  for (auto& sample : batch) {
    sample->sequence = impl_->next_sequence++;
    callback(std::move(sample));
  }
  return !woken;
}

void RawTopics::wake() { impl_->wake.trigger(); }

void RawTopics::setActive(std::size_t i, bool active) { impl_->setActive(i, active); }
bool RawTopics::active(std::size_t i) const { return impl_->readers.at(i).has_value(); }

std::uint32_t RawTopics::matchedWriters(std::size_t i) const {
  return impl_->readers.at(i) ? impl_->readers[i]->matchedWriters() : 0;
}

std::uint64_t RawTopics::samplesLost(std::size_t i) const {
  if (!impl_->readers.at(i)) return 0;
  dds_sample_lost_status_t status;
  dds::check(dds_get_sample_lost_status(impl_->readers[i]->handle(), &status),
             "dds_get_sample_lost_status");
  return status.total_count;
}

std::uint64_t RawTopics::samplesRejected(std::size_t i) const {
  if (!impl_->readers.at(i)) return 0;
  dds_sample_rejected_status_t status;
  dds::check(dds_get_sample_rejected_status(impl_->readers[i]->handle(), &status),
             "dds_get_sample_rejected_status");
  return status.total_count;
}

std::uint32_t RawTopics::incompatibleWriters(std::size_t i, std::int32_t* last_policy) const {
  if (!impl_->readers.at(i)) return 0;
  dds_requested_incompatible_qos_status_t status;
  dds::check(dds_get_requested_incompatible_qos_status(impl_->readers[i]->handle(), &status),
             "dds_get_requested_incompatible_qos_status");
  if (last_policy != nullptr) *last_policy = static_cast<std::int32_t>(status.last_policy_id);
  return status.total_count;
}

}  // namespace sl::view
