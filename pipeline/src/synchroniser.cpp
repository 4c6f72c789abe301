#include "sl/pipeline/synchroniser.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace sl::pipeline {

Synchroniser::Synchroniser(std::vector<std::string> camera_ids, SynchroniserOptions options)
    : camera_ids_(std::move(camera_ids)), options_(options), frames_(camera_ids_.size()) {
  if (camera_ids_.empty()) throw std::invalid_argument("Synchroniser: no cameras");
  if (options_.image_interval_ns <= 0) {
    throw std::invalid_argument("Synchroniser: image_interval_ns must be positive");
  }
  if (!(options_.tolerance_lower >= 0 && options_.tolerance_upper >= 0 &&
        options_.tolerance_lower + options_.tolerance_upper < 1.0)) {
    throw std::invalid_argument(
        "Synchroniser: tolerances must be >= 0 and sum to less than 1 so that the windows of "
        "consecutive frames do not overlap");
  }
  if (options_.max_age_ns <= 0) throw std::invalid_argument("Synchroniser: max_age_ns must be > 0");
}

void Synchroniser::setPattern(std::string pattern_name, int frame_count) {
  if (frame_count < 1) throw std::invalid_argument("Synchroniser: frame_count must be >= 1");
  counters_.triggers_incomplete += triggers_.size();
  triggers_.clear();
  for (auto& queue : frames_) {
    counters_.frames_unmatched += queue.size();
    queue.clear();
  }
  pattern_name_ = std::move(pattern_name);
  frame_count_ = frame_count;
}

void Synchroniser::pushTrigger(TimestampNs trigger_stamp_ns) {
  // Kept sorted so that sequences complete oldest first.
  triggers_.insert(std::upper_bound(triggers_.begin(), triggers_.end(), trigger_stamp_ns),
                   trigger_stamp_ns);
  newest_stamp_ns_ = std::max(newest_stamp_ns_, trigger_stamp_ns);
  match();
  purge(newest_stamp_ns_);
}

void Synchroniser::pushFrame(std::size_t camera_index, Frame frame) {
  if (camera_index >= frames_.size()) {
    throw std::out_of_range("Synchroniser: camera index " + std::to_string(camera_index) +
                            " but only " + std::to_string(frames_.size()) + " cameras");
  }
  newest_stamp_ns_ = std::max(newest_stamp_ns_, frame.stamp_ns);
  frames_[camera_index].push_back(std::move(frame));
  match();
  purge(newest_stamp_ns_);
}

std::vector<std::shared_ptr<const ImageSet>> Synchroniser::takeCompleted() {
  std::vector<std::shared_ptr<const ImageSet>> out;
  out.swap(completed_);
  return out;
}

void Synchroniser::match() {
  if (frame_count_ < 1) return;
  const double dt = static_cast<double>(options_.image_interval_ns);
  const auto lower = static_cast<TimestampNs>(std::llround(options_.tolerance_lower * dt));
  const auto upper = static_cast<TimestampNs>(std::llround(options_.tolerance_upper * dt));

  // For each camera and pattern index, the position of the matching frame in
  // that camera's queue (-1: not arrived).
  std::vector<std::vector<std::ptrdiff_t>> picks(frames_.size(),
                                                 std::vector<std::ptrdiff_t>(frame_count_));
  for (auto trigger = triggers_.begin(); trigger != triggers_.end();) {
    bool complete = true;
    for (std::size_t c = 0; c < frames_.size() && complete; ++c) {
      const std::deque<Frame>& queue = frames_[c];
      for (int i = 0; i < frame_count_ && complete; ++i) {
        const TimestampNs expected = *trigger + i * options_.image_interval_ns;
        const auto found = std::find_if(queue.begin(), queue.end(), [&](const Frame& f) {
          const TimestampNs d = f.stamp_ns - expected;
          return d >= -lower && d <= upper;
        });
        if (found == queue.end()) {
          complete = false;
        } else {
          picks[c][i] = found - queue.begin();
        }
      }
    }
    if (!complete) {
      ++trigger;
      continue;
    }

    auto set = std::make_shared<ImageSet>();
    set->sequence_id = next_sequence_id_++;
    set->pattern_name = pattern_name_;
    set->trigger_stamp_ns = *trigger;
    set->cameras.resize(frames_.size());
    for (std::size_t c = 0; c < frames_.size(); ++c) {
      CameraImages& images = set->cameras[c];
      std::deque<Frame>& queue = frames_[c];
      images.camera_id = camera_ids_[c];
      images.bit_depth = queue[picks[c][0]].bit_depth;
      for (int i = 0; i < frame_count_; ++i) {
        Frame& f = queue[picks[c][i]];
        images.frames.push_back(std::move(f.image));
        images.stamps_ns.push_back(f.stamp_ns);
      }
      // Erase the used frames, highest position first.
      std::vector<std::ptrdiff_t> used = picks[c];
      std::sort(used.rbegin(), used.rend());
      for (std::ptrdiff_t pos : used) queue.erase(queue.begin() + pos);
    }
    completed_.push_back(std::move(set));
    ++counters_.sets_completed;
    trigger = triggers_.erase(trigger);
  }
}

void Synchroniser::purge(TimestampNs newest) {
  const TimestampNs cutoff = newest - options_.max_age_ns;
  // A trigger older than the cutoff is given up. A frame is dropped once every
  // trigger it could belong to (t_p <= t_c + tol_l * dt) is older than the
  // cutoff, so a frame is never dropped while its trigger is still pending.
  while (!triggers_.empty() && triggers_.front() < cutoff) {
    triggers_.pop_front();
    ++counters_.triggers_incomplete;
  }
  const auto lower = static_cast<TimestampNs>(
      std::llround(options_.tolerance_lower * static_cast<double>(options_.image_interval_ns)));
  for (auto& queue : frames_) {
    const auto old = std::remove_if(queue.begin(), queue.end(), [&](const Frame& f) {
      return f.stamp_ns + lower < cutoff;
    });
    counters_.frames_unmatched += static_cast<std::uint64_t>(queue.end() - old);
    queue.erase(old, queue.end());
  }
}

}  // namespace sl::pipeline
