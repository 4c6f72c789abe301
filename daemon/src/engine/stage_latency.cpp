#include "engine/stage_latency.h"

#include <algorithm>
#include <vector>

namespace sl::daemon {

namespace {

double median(std::vector<double> v) {
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  double m = v[mid];
  if (v.size() % 2 == 0) m = (m + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid))) / 2;
  return m;
}

double positiveMs(pipeline::TimestampNs from, pipeline::TimestampNs to) {
  return to > from ? static_cast<double>(to - from) * 1e-6 : 0.0;
}

}  // namespace

pipeline::TimestampNs lastExposureNs(const pipeline::ImageSet& set) {
  pipeline::TimestampNs last = set.trigger_stamp_ns;
  for (const auto& camera : set.cameras)
    for (const pipeline::TimestampNs stamp : camera.stamps_ns) last = std::max(last, stamp);
  return last;
}

StageTimes stageTimes(pipeline::TimestampNs exposed_ns, pipeline::TimestampNs processing_ns,
                      pipeline::TimestampNs processed_ns, pipeline::TimestampNs published_ns) {
  return {positiveMs(exposed_ns, processing_ns), positiveMs(processing_ns, processed_ns),
          positiveMs(processed_ns, published_ns)};
}

void StageLatency::add(const StageTimes& scan) {
  std::lock_guard lock(mutex_);
  ring_[next_] = scan;
  next_ = (next_ + 1) % kWindow;
  count_ = std::min(count_ + 1, kWindow);
}

void StageLatency::clear() {
  std::lock_guard lock(mutex_);
  next_ = 0;
  count_ = 0;
}

StageSummary StageLatency::summary() const {
  std::lock_guard lock(mutex_);
  StageSummary s;
  s.scans = count_;
  if (count_ == 0) return s;
  std::vector<double> wait, processing, publish, total;
  for (std::size_t i = 0; i < count_; ++i) {
    const StageTimes& t = ring_[i];
    wait.push_back(t.wait_ms);
    processing.push_back(t.processing_ms);
    publish.push_back(t.publish_ms);
    total.push_back(t.totalMs());
  }
  s.median = {median(wait), median(processing), median(publish)};
  s.total_median_ms = median(total);
  s.total_max_ms = *std::max_element(total.begin(), total.end());
  return s;
}

}  // namespace sl::daemon
