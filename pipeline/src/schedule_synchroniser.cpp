#include "sl/pipeline/schedule_synchroniser.h"

#include <cmath>
#include <utility>

namespace sl::pipeline {

namespace {

// Schedules kept at most: switches come seconds apart, a schedule retires
// max_age after its boundary; more means switches faster than sequences.
constexpr std::size_t kMaxSchedules = 8;

void add(SynchroniserCounters& total, const SynchroniserCounters& c) {
  total.sets_completed += c.sets_completed;
  total.frames_unmatched += c.frames_unmatched;
  total.triggers_incomplete += c.triggers_incomplete;
}

}  // namespace

ScheduleSynchroniser::ScheduleSynchroniser(std::vector<std::string> camera_ids,
                                           SynchroniserOptions options)
    : camera_ids_(std::move(camera_ids)), options_(options) {
  Synchroniser check(camera_ids_, options_);  // validates ids and options
}

void ScheduleSynchroniser::startRun(std::string pattern, int frame_count,
                                    TimestampNs not_before_ns) {
  retireAll(true);
  Schedule schedule{Synchroniser(camera_ids_, options_), not_before_ns, kNoHold};
  schedule.synchroniser.setPattern(std::move(pattern), frame_count);
  schedules_.push_back(std::move(schedule));
  running_ = true;
  hold_from_ns_ = kNoHold;
  last_trigger_ns_ = 0;
  next_sequence_id_ = 0;
}

void ScheduleSynchroniser::switchPattern(std::string pattern, int frame_count,
                                         TimestampNs not_before_ns, TimestampNs boundary_ns) {
  if (!running_) {
    startRun(std::move(pattern), frame_count, not_before_ns);
    return;
  }
  schedules_.back().until_ns = boundary_ns;
  Schedule schedule{Synchroniser(camera_ids_, options_), not_before_ns, kNoHold};
  schedule.synchroniser.setPattern(std::move(pattern), frame_count);
  schedules_.push_back(std::move(schedule));
  while (schedules_.size() > kMaxSchedules) {
    retire(schedules_.front(), true);
    schedules_.pop_front();
  }
  hold_from_ns_ = kNoHold;
  last_trigger_ns_ = 0;
}

void ScheduleSynchroniser::holdFrom(TimestampNs at_ns) {
  if (running_) hold_from_ns_ = at_ns;
}

void ScheduleSynchroniser::endRun(bool count_pending) {
  retireAll(count_pending);
  running_ = false;
  hold_from_ns_ = kNoHold;
  last_trigger_ns_ = 0;
}

void ScheduleSynchroniser::pushFrame(std::size_t camera_index, Frame frame) {
  if (camera_index >= camera_ids_.size())
    throw std::out_of_range("ScheduleSynchroniser: camera index " + std::to_string(camera_index) +
                            " but only " + std::to_string(camera_ids_.size()) + " cameras");
  const TimestampNs stamp = frame.stamp_ns;
  Schedule* schedule = route(stamp);
  if (!schedule) return;
  schedule->synchroniser.pushFrame(camera_index, std::move(frame));
  collect(*schedule);
  retireExpired(stamp);
}

void ScheduleSynchroniser::pushTrigger(TimestampNs trigger_stamp_ns) {
  Schedule* schedule = route(trigger_stamp_ns);
  if (!schedule) return;
  schedule->synchroniser.pushTrigger(trigger_stamp_ns);
  if (running_ && schedule == &schedules_.back()) last_trigger_ns_ = trigger_stamp_ns;
  collect(*schedule);
  retireExpired(trigger_stamp_ns);
}

std::vector<std::shared_ptr<const ImageSet>> ScheduleSynchroniser::takeCompleted() {
  std::vector<std::shared_ptr<const ImageSet>> out;
  out.swap(completed_);
  return out;
}

ScheduleCounters ScheduleSynchroniser::counters() const {
  SynchroniserCounters total = retired_;
  for (const Schedule& s : schedules_) add(total, s.synchroniser.counters());
  return {total.sets_completed, total.frames_unmatched, total.triggers_incomplete, stamps_outside_};
}

// The schedule whose stamp interval holds `stamp` (the running one ends at
// the pending switch's boundary); nullptr when none does.
ScheduleSynchroniser::Schedule* ScheduleSynchroniser::route(TimestampNs stamp) {
  // A boundary is the start of a sequence that does not belong to the
  // schedule: its first frame may be stamped up to tol_l * dt before it.
  const auto lower = static_cast<TimestampNs>(
      std::llround(options_.tolerance_lower * static_cast<double>(options_.image_interval_ns)));
  for (std::size_t i = 0; i < schedules_.size(); ++i) {
    Schedule& s = schedules_[i];
    const bool is_running = running_ && i + 1 == schedules_.size();
    const TimestampNs boundary = is_running ? std::min(s.until_ns, hold_from_ns_) : s.until_ns;
    const TimestampNs until = boundary == kNoHold ? kNoHold : boundary - lower;
    if (stamp >= s.from_ns && stamp < until) return &s;
  }
  ++stamps_outside_;
  return nullptr;
}

void ScheduleSynchroniser::collect(Schedule& schedule) {
  for (auto& set : schedule.synchroniser.takeCompleted()) {
    // Renumbered so that ids run on across the run's switches (each
    // schedule's Synchroniser counts from 0); the frames are shared.
    auto renumbered = std::make_shared<ImageSet>(*set);
    renumbered->sequence_id = next_sequence_id_++;
    completed_.push_back(std::move(renumbered));
  }
}

void ScheduleSynchroniser::retire(Schedule& schedule, bool count_pending) {
  if (count_pending) schedule.synchroniser.setPattern("retired", 1);  // counts what it holds
  collect(schedule);
  add(retired_, schedule.synchroniser.counters());
}

void ScheduleSynchroniser::retireAll(bool count_pending) {
  for (Schedule& s : schedules_) retire(s, count_pending);
  schedules_.clear();
}

// Retires the schedules that stopped at a boundary more than max_age before
// `stamp`: their last sequence is long complete or lost.
void ScheduleSynchroniser::retireExpired(TimestampNs stamp) {
  const std::size_t stopped = running_ ? schedules_.size() - 1 : schedules_.size();
  std::size_t expired = 0;
  while (expired < stopped && schedules_[expired].until_ns != kNoHold &&
         stamp > schedules_[expired].until_ns + options_.max_age_ns)
    ++expired;
  for (std::size_t i = 0; i < expired; ++i) {
    retire(schedules_.front(), true);
    schedules_.pop_front();
  }
}

}  // namespace sl::pipeline
