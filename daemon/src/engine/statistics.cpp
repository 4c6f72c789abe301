#include "engine/statistics.h"

namespace sl::daemon {

void EngineStatistics::setTriggerGrouping(GroupingCounts counts) {
  unmatched_trigger_ = counts.frames_unmatched;
  incomplete_trigger_ = counts.sets_incomplete;
}

void EngineStatistics::setSoftwareGrouping(GroupingCounts counts) {
  unmatched_software_ = counts.frames_unmatched;
  incomplete_software_ = counts.sets_incomplete;
}

std::uint64_t EngineStatistics::framesUnmatched() const {
  return unmatched_trigger_.load() + unmatched_software_.load();
}

std::uint64_t EngineStatistics::setsIncomplete() const {
  return incomplete_trigger_.load() + incomplete_software_.load();
}

void EngineStatistics::scanPublished(std::uint64_t generation) {
  std::lock_guard lock(mutex_);
  if (generation != scan_generation_) {
    scan_generation_ = generation;
    recent_.clear();
  }
  recent_.push_back(Clock::now());
  if (recent_.size() > 10) recent_.pop_front();
  incomplete_at_scan_ = setsIncomplete();
}

double EngineStatistics::scanRateHz(std::uint64_t generation, double stall_s) const {
  std::lock_guard lock(mutex_);
  if (generation != scan_generation_ || recent_.size() < 2) return 0;
  const auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  const double intervals = static_cast<double>(recent_.size() - 1);
  const double span_s = seconds(recent_.back() - recent_.front());
  const double since_last_s = seconds(Clock::now() - recent_.back());
  if (!(span_s > 0)) return 0;
  if (since_last_s >= stall_s) return 0;
  if (since_last_s > 1.5 * span_s / intervals) return intervals / (span_s + since_last_s);
  return intervals / span_s;
}

std::optional<EngineStatistics::Clock::time_point> EngineStatistics::lastScan(std::uint64_t generation) const {
  std::lock_guard lock(mutex_);
  if (generation != scan_generation_ || recent_.empty()) return std::nullopt;
  return recent_.back();
}

double EngineStatistics::frameRateHz() {
  std::lock_guard lock(mutex_);
  const auto now = Clock::now();
  const double window_s = std::chrono::duration<double>(now - window_start_).count();
  if (window_s >= 1.0) {
    const std::uint64_t frames = frames_received_.load();
    frame_rate_hz_ = (frames - window_frames_) / window_s;
    window_frames_ = frames;
    window_start_ = now;
  }
  return frame_rate_hz_;
}

void EngineStatistics::fillStatus(EngineStatus& s) {
  s.sets_incomplete = setsIncomplete();
  s.frame_rate_hz = frameRateHz();
  s.frames_received = frames_received_.load();
  const StageSummary stages = stageSummary();
  s.latency_ms = stages.total_median_ms;
  s.latency_max_ms = stages.total_max_ms;
  s.wait_ms = stages.median.wait_ms;
  s.processing_ms = stages.median.processing_ms;
  s.publish_ms = stages.median.publish_ms;
}

void addRecorderStatus(EngineStatus& s, const Recorder& recorder, double last_error_hold_s,
                       pipeline::TimestampNs now_ns) {
  s.sets_not_recorded = recorder.notRecorded();
  s.sets_dropped += s.sets_not_recorded;
  s.sets_recorded = recorder.written();
  s.sets_over_quota = recorder.overQuota();
  if (!s.recording.empty() && !recorder.active()) s.recording.clear();  // stopped by itself
  const Recorder::Error error = recorder.lastError();
  s.errors_reported += error.count;
  const double hold_ns = last_error_hold_s * 1e9;
  const bool aged = hold_ns > 0 && static_cast<double>(now_ns - error.stamp_ns) > hold_ns;
  if (!error.message.empty() && !aged && error.stamp_ns >= s.last_error_ns) {
    s.last_error = error.message;
    s.last_error_ns = error.stamp_ns;
  }
}

}  // namespace sl::daemon
