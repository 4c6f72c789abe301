#include "sl/drivers/replay.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <list>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "sl/drivers/recording.h"

namespace sl::drivers {

namespace {

using pipeline::TimestampNs;

constexpr TimestampNs kStartDelayNs = 20'000'000;

// What the schedule needs of a set without loading its images.
struct SetInfo {
  std::size_t index = 0;  // in the recording
  std::string pattern;
  TimestampNs trigger_ns = 0;
  std::vector<std::vector<TimestampNs>> offsets_ns;  // per camera, per frame: stamp - trigger
  std::vector<int> bit_depths;
};

class Replay : public ReplaySensor, public std::enable_shared_from_this<Replay> {
 public:
  explicit Replay(const ReplayConfig& config)
      : config_(config), recording_(RecordingReader::open(config.dir)) {
    for (std::size_t index = 0; index < recording_->size(); ++index) {
      const pipeline::ImageSet& set = recording_->info(index);
      SetInfo info{index, set.pattern_name, set.trigger_stamp_ns, {}, {}};
      for (const auto& camera : set.cameras) {
        std::vector<TimestampNs> offsets;
        for (TimestampNs s : camera.stamps_ns) offsets.push_back(s - set.trigger_stamp_ns);
        info.offsets_ns.push_back(std::move(offsets));
        info.bit_depths.push_back(camera.bit_depth);
        if (sets_.empty()) camera_ids_.push_back(camera.camera_id);
      }
      if (info.offsets_ns.size() != camera_ids_.size())
        throw std::runtime_error(recording_->where(index) + ": camera count differs from the first set's");
      if (std::find(patterns_.begin(), patterns_.end(), info.pattern) == patterns_.end())
        patterns_.push_back(info.pattern);
      sets_.push_back(std::move(info));
    }
    if (sets_.empty()) throw std::runtime_error(config.dir + ": the recording holds no image sets");
    selected_ = patterns_.front();
  }

  std::vector<std::shared_ptr<Camera>> cameras() override;
  std::shared_ptr<Projector> projector() override;
  std::shared_ptr<TriggerSource> triggerSource() override;
  std::size_t setCount() const override { return sets_.size(); }

  // --- Projector ---
  std::vector<ProjectorSequence> sequences() const {
    std::vector<ProjectorSequence> out;
    for (const auto& p : patterns_) {
      const auto it = std::find_if(sets_.begin(), sets_.end(),
                                   [&](const SetInfo& s) { return s.pattern == p; });
      out.push_back({p, static_cast<int>(it->offsets_ns.front().size())});
    }
    return out;
  }
  void select(const std::string& name) {
    std::lock_guard lock(mutex_);
    if (std::find(patterns_.begin(), patterns_.end(), name) == patterns_.end())
      throw std::invalid_argument("replay: the recording has no pattern '" + name + "'");
    if (runningLocked()) throw std::logic_error("replay: cannot select while running");
    selected_ = name;
  }
  void start(int count) {
    if (count < 0) throw std::invalid_argument("replay: count must be >= 0");
    std::lock_guard lock(mutex_);
    if (runningLocked()) throw std::logic_error("replay: already running");
    playlist_.clear();
    for (std::size_t i = 0; i < sets_.size(); ++i)
      if (sets_[i].pattern == selected_) playlist_.push_back(i);
    // The recorded trigger interval of this pattern (median over neighbouring
    // sets); with a single set, its frame span plus one frame interval.
    std::vector<TimestampNs> gaps;
    for (std::size_t i = 1; i < playlist_.size(); ++i)
      gaps.push_back(sets_[playlist_[i]].trigger_ns - sets_[playlist_[i - 1]].trigger_ns);
    std::sort(gaps.begin(), gaps.end());
    const std::vector<TimestampNs>& offsets = sets_[playlist_.front()].offsets_ns.front();
    const TimestampNs span = offsets.back();
    const TimestampNs frame_interval =
        offsets.size() > 1 ? span / TimestampNs(offsets.size() - 1) : 33'333'333;
    period_ns_ = std::max(gaps.empty() ? 0 : gaps[gaps.size() / 2], span + frame_interval);
    const std::size_t available = config_.loop ? SIZE_MAX : playlist_.size();
    count_ = count == 0 ? available : std::min<std::size_t>(count, available);
    t0_ns_ = pipeline::systemClockNs() + kStartDelayNs;
    ++generation_;
    stopped_ = false;
    std::fill(camera_next_.begin(), camera_next_.end(), 0);
    trigger_next_ = 0;
    cv_.notify_all();
  }
  void stop() {
    std::lock_guard lock(mutex_);
    stopped_ = true;
    ++generation_;
    cv_.notify_all();
  }

  // --- Camera c: frames in schedule order ---
  std::optional<pipeline::Frame> grab(std::size_t c, std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    const std::uint64_t epoch = camera_epoch_[c];
    for (;;) {
      if (camera_epoch_[c] != epoch) return std::nullopt;  // Camera::stop()
      if (!stopped_ && generation_ > 0) {
        const std::size_t frames = frameCount();
        const std::size_t j = camera_next_[c];
        const std::size_t k = j / frames, i = j % frames;
        if (k < count_) {
          const SetInfo& info = sets_[playlist_[k % playlist_.size()]];
          const TimestampNs stamp = t0_ns_ + TimestampNs(k) * period_ns_ + info.offsets_ns[c][i];
          if (pipeline::systemClockNs() >= stamp) {
            ++camera_next_[c];
            const std::size_t set_index = info.index;
            const int bit_depth = info.bit_depths[c];
            lock.unlock();
            pipeline::Frame frame;
            frame.image = loadFrame(set_index, c, i);
            // A frame of another size or depth than the recording's first set
            // would be dropped later without a name: refused here, naming
            // the file (the engine reports it; the set counts as incomplete).
            if (c < camera_sizes_.size() && (frame.image.cols != camera_sizes_[c].width ||
                                              frame.image.rows != camera_sizes_[c].height ||
                                              frame.image.depth() != camera_depths_[c]))
              throw std::runtime_error(
                  recording_->whereFrame(set_index, camera_ids_[c], i) + ": " +
                  std::to_string(frame.image.cols) + "x" +
                  std::to_string(frame.image.rows) +
                  (frame.image.depth() == CV_16U ? " 16-bit" : " 8-bit") + " frame, the recording's camera '" +
                  camera_ids_[c] + "' is " + std::to_string(camera_sizes_[c].width) + "x" +
                  std::to_string(camera_sizes_[c].height) +
                  (camera_depths_[c] == CV_16U ? " 16-bit" : " 8-bit"));
            frame.stamp_ns = stamp;
            frame.frame_id = j;
            frame.bit_depth = bit_depth;
            return frame;
          }
          if (waitUntil(lock, stamp, deadline)) continue;
          return std::nullopt;
        }
      }
      if (cv_.wait_until(lock, deadline) == std::cv_status::timeout) return std::nullopt;
    }
  }
  void stopCamera(std::size_t c) {
    std::lock_guard lock(mutex_);
    ++camera_epoch_[c];
    cv_.notify_all();
  }

  // --- Trigger source ---
  std::optional<TriggerEvent> next(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    const std::uint64_t epoch = trigger_epoch_;
    for (;;) {
      if (trigger_epoch_ != epoch) return std::nullopt;
      if (!stopped_ && generation_ > 0 && trigger_next_ < count_) {
        const TimestampNs stamp = t0_ns_ + TimestampNs(trigger_next_) * period_ns_;
        if (pipeline::systemClockNs() >= stamp) return TriggerEvent{stamp, trigger_next_++};
        if (waitUntil(lock, stamp, deadline)) continue;
        return std::nullopt;
      }
      if (cv_.wait_until(lock, deadline) == std::cv_status::timeout) return std::nullopt;
    }
  }
  void stopTriggers() {
    std::lock_guard lock(mutex_);
    ++trigger_epoch_;
    cv_.notify_all();
  }

  const std::vector<std::string>& cameraIds() const { return camera_ids_; }
  // The first set's frame size and depth per camera (set by cameras()).
  std::vector<cv::Size> camera_sizes_;
  std::vector<int> camera_depths_;

 private:
  bool runningLocked() const {
    if (stopped_ || generation_ == 0) return false;
    return count_ == SIZE_MAX || trigger_next_ < count_ ||
           std::any_of(camera_next_.begin(), camera_next_.end(),
                       [&](std::size_t j) { return j < count_ * frameCount(); });
  }
  std::size_t frameCount() const { return sets_[playlist_.front()].offsets_ns.front().size(); }

  // Waits until `stamp` (system clock) or `deadline`; true if `stamp` may
  // have come (re-check state), false on the deadline.
  bool waitUntil(std::unique_lock<std::mutex>& lock, TimestampNs stamp,
                 std::chrono::steady_clock::time_point deadline) {
    const auto until_stamp =
        std::chrono::steady_clock::now() +
        std::chrono::nanoseconds(std::max<TimestampNs>(0, stamp - pipeline::systemClockNs()));
    cv_.wait_until(lock, std::min(until_stamp, deadline));
    return std::chrono::steady_clock::now() < deadline || pipeline::systemClockNs() >= stamp;
  }

  // One frame of a set, from the cache or after reading the whole set (the
  // cameras read the same set). The cache keeps the most recently used sets
  // within config_.cache_bytes, and always the one just read.
  cv::Mat loadFrame(std::size_t set_index, std::size_t camera, std::size_t i) {
    std::lock_guard lock(cache_mutex_);
    auto it = std::find_if(cache_.begin(), cache_.end(),
                           [&](const CachedSet& c) { return c.index == set_index; });
    if (it != cache_.end()) {
      cache_.splice(cache_.begin(), cache_, it);
    } else {
      CachedSet entry{set_index, recording_->load(set_index), 0};
      for (const auto& c : entry.set.cameras)
        for (const cv::Mat& f : c.frames) entry.bytes += f.total() * f.elemSize();
      cache_bytes_ += entry.bytes;
      cache_.push_front(std::move(entry));
      while (cache_.size() > 1 && cache_bytes_ > config_.cache_bytes) {
        cache_bytes_ -= cache_.back().bytes;
        cache_.pop_back();
      }
    }
    return cache_.front().set.cameras.at(camera).frames.at(i);
  }

  const ReplayConfig config_;
  const std::unique_ptr<const RecordingReader> recording_;
  std::vector<SetInfo> sets_;
  std::vector<std::string> camera_ids_;
  std::vector<std::string> patterns_;

  std::mutex mutex_;
  std::condition_variable cv_;
  std::string selected_;                        // guarded by mutex_
  std::vector<std::size_t> playlist_;           // guarded by mutex_
  std::size_t count_ = 0;                       // guarded by mutex_
  TimestampNs t0_ns_ = 0, period_ns_ = 0;       // guarded by mutex_
  std::uint64_t generation_ = 0;                // guarded by mutex_
  bool stopped_ = false;                        // guarded by mutex_
  std::vector<std::size_t> camera_next_ = std::vector<std::size_t>(8, 0);      // guarded
  std::vector<std::uint64_t> camera_epoch_ = std::vector<std::uint64_t>(8, 0);  // guarded
  std::uint64_t trigger_next_ = 0;              // guarded by mutex_
  std::uint64_t trigger_epoch_ = 0;             // guarded by mutex_

  struct CachedSet {
    std::size_t index;
    pipeline::ImageSet set;
    std::size_t bytes = 0;
  };
  std::mutex cache_mutex_;
  std::list<CachedSet> cache_;    // most recently used first; guarded by cache_mutex_
  std::size_t cache_bytes_ = 0;   // guarded by cache_mutex_
};

class ReplayCamera : public Camera {
 public:
  ReplayCamera(std::shared_ptr<Replay> replay, std::size_t index, int width, int height)
      : replay_(std::move(replay)), index_(index), width_(width), height_(height) {}
  std::string id() const override { return replay_->cameraIds()[index_]; }
  int width() const override { return width_; }
  int height() const override { return height_; }
  void start() override {}
  void stop() override { replay_->stopCamera(index_); }
  std::optional<pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    return replay_->grab(index_, timeout);
  }

 private:
  std::shared_ptr<Replay> replay_;
  std::size_t index_;
  int width_, height_;
};

class ReplayProjector : public Projector {
 public:
  explicit ReplayProjector(std::shared_ptr<Replay> replay) : replay_(std::move(replay)) {}
  std::string id() const override { return "replay"; }
  std::vector<ProjectorSequence> sequences() const override { return replay_->sequences(); }
  void select(const std::string& name) override { replay_->select(name); }
  void start(int count) override { replay_->start(count); }
  void stop() override { replay_->stop(); }

 private:
  std::shared_ptr<Replay> replay_;
};

class ReplayTrigger : public TriggerSource {
 public:
  explicit ReplayTrigger(std::shared_ptr<Replay> replay) : replay_(std::move(replay)) {}
  std::optional<TriggerEvent> next(std::chrono::milliseconds timeout) override {
    return replay_->next(timeout);
  }
  void stop() override { replay_->stopTriggers(); }

 private:
  std::shared_ptr<Replay> replay_;
};

std::vector<std::shared_ptr<Camera>> Replay::cameras() {
  const pipeline::ImageSet first = recording_->load(sets_.front().index);
  std::vector<std::shared_ptr<Camera>> out;
  for (std::size_t c = 0; c < camera_ids_.size(); ++c) {
    const cv::Mat& image = first.cameras[c].frames.front();
    camera_sizes_.push_back(image.size());
    camera_depths_.push_back(image.depth());
    out.push_back(std::make_shared<ReplayCamera>(shared_from_this(), c, image.cols, image.rows));
  }
  return out;
}

std::shared_ptr<Projector> Replay::projector() {
  return std::make_shared<ReplayProjector>(shared_from_this());
}

std::shared_ptr<TriggerSource> Replay::triggerSource() {
  return std::make_shared<ReplayTrigger>(shared_from_this());
}

}  // namespace

std::shared_ptr<ReplaySensor> ReplaySensor::open(const ReplayConfig& config) {
  auto replay = std::make_shared<Replay>(config);
  if (replay->cameraIds().size() > 8)
    throw std::runtime_error(config.dir + ": more than 8 cameras in the recording");
  return replay;
}

}  // namespace sl::drivers
