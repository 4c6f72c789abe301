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
}

double EngineStatistics::scanRateHz(std::uint64_t generation) const {
  std::lock_guard lock(mutex_);
  if (generation != scan_generation_ || recent_.size() < 2) return 0;
  return (recent_.size() - 1) / std::chrono::duration<double>(recent_.back() - recent_.front()).count();
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

}  // namespace sl::daemon
