#include "sim_live.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "sim_render.h"

namespace sl::drivers::sim {

namespace {

std::int64_t deadlineAfter(std::chrono::milliseconds timeout) {
  return pipeline::systemClockNs() + std::chrono::duration_cast<std::chrono::nanoseconds>(
                                         std::max(timeout, std::chrono::milliseconds(0)))
                                         .count();
}

}  // namespace

LiveSchedule::LiveSchedule(std::vector<ProjectorSequence> sequences, double camera_fps,
                           int bit_depth, std::uint64_t seed, RenderFunction render,
                           int camera_count)
    : sequences_(std::move(sequences)),
      frame_interval_ns_(1e9 / camera_fps),
      bit_depth_(bit_depth),
      seed_(seed),
      render_(std::move(render)),
      cameras_(static_cast<std::size_t>(std::max(camera_count, 1))) {
  if (sequences_.empty()) throw std::invalid_argument("LiveSchedule: no sequences");
  if (camera_count < 1) throw std::invalid_argument("LiveSchedule: camera_count must be >= 1");
}

// --- schedule arithmetic (mutex_ held) ---

std::int64_t LiveSchedule::frameStamp(std::int64_t j) const {
  return t0_ns_ + std::llround(double(j) * frame_interval_ns_);
}

std::int64_t LiveSchedule::frameLimit() const {
  return sequence_count_ == 0 ? kNever : sequence_count_ * frames_per_sequence_;
}

bool LiveSchedule::frameExists(std::int64_t j) const {
  return generation_ != 0 && j >= 0 && j < frameLimit() &&
         (stop_ns_ == kNever || frameStamp(j) < stop_ns_);
}

std::int64_t LiveSchedule::lastStampAtOrBefore(std::int64_t t_ns) const {
  if (t_ns < t0_ns_) return -1;
  auto j = static_cast<std::int64_t>(std::floor(double(t_ns - t0_ns_) / frame_interval_ns_));
  while (j >= 0 && frameStamp(j) > t_ns) --j;
  while (frameStamp(j + 1) <= t_ns) ++j;
  return j;
}

std::int64_t LiveSchedule::lastFrameAtOrBefore(std::int64_t t_ns) const {
  if (generation_ == 0) return -1;
  std::int64_t j = lastStampAtOrBefore(t_ns);
  if (frameLimit() != kNever) j = std::min(j, frameLimit() - 1);
  if (stop_ns_ != kNever) j = std::min(j, lastStampAtOrBefore(stop_ns_ - 1));
  return j;
}

bool LiveSchedule::runningLocked(std::int64_t now_ns) const {
  if (generation_ == 0) return false;
  std::int64_t end = stop_ns_;
  if (frameLimit() != kNever) end = std::min(end, frameStamp(frameLimit()));
  return now_ns < end;
}

void LiveSchedule::waitUntil(std::unique_lock<std::mutex>& lock, std::int64_t t_ns) {
  const std::chrono::system_clock::time_point until(
      std::chrono::duration_cast<std::chrono::system_clock::duration>(
          std::chrono::nanoseconds(t_ns)));
  cv_.wait_until(lock, until);
}

// --- projector ---

void LiveSchedule::select(const std::string& name) {
  const auto it = std::find_if(sequences_.begin(), sequences_.end(),
                               [&](const ProjectorSequence& s) { return s.name == name; });
  if (it == sequences_.end()) {
    std::string known;
    for (const ProjectorSequence& s : sequences_) known += (known.empty() ? "" : ", ") + s.name;
    throw std::invalid_argument("projector: unknown pattern '" + name + "' (known: " + known + ")");
  }
  std::lock_guard lock(mutex_);
  if (runningLocked(pipeline::systemClockNs()))
    throw std::logic_error("projector: select('" + name + "') while running; stop() first");
  selected_ = static_cast<std::size_t>(it - sequences_.begin());
}

void LiveSchedule::startProjector(int count) {
  if (count < 0) throw std::invalid_argument("projector: start count must be >= 0");
  {
    std::lock_guard lock(mutex_);
    const std::int64_t now = pipeline::systemClockNs();
    if (runningLocked(now)) throw std::logic_error("projector: start() while running");
    ++generation_;
    running_pattern_ = selected_;
    frames_per_sequence_ = sequences_[selected_].frame_count;
    sequence_count_ = count;
    t0_ns_ = now + kStartDelayNs;
    stop_ns_ = kNever;
    triggers_stopped_ = false;
    held_frame_ = -1;
  }
  cv_.notify_all();
}

void LiveSchedule::stopProjector() {
  {
    std::lock_guard lock(mutex_);
    if (generation_ != 0) stop_ns_ = std::min(stop_ns_, pipeline::systemClockNs());
    held_frame_ = -1;
  }
  cv_.notify_all();
}

void LiveSchedule::projectSingle(int index) {
  std::lock_guard lock(mutex_);
  if (runningLocked(pipeline::systemClockNs()))
    throw std::logic_error("projector: projectSingle() while a sequence runs; stop() first");
  if (index < 0 || index >= sequences_[selected_].frame_count)
    throw std::out_of_range("projector: pattern " + std::to_string(index) + " of '" +
                            sequences_[selected_].name + "', which has " +
                            std::to_string(sequences_[selected_].frame_count));
  held_frame_ = index;
}

// --- camera ---

void LiveSchedule::armCamera(int camera) {
  std::lock_guard lock(mutex_);
  CameraState& c = cameras_.at(static_cast<std::size_t>(camera));
  if (c.armed) return;
  c.armed = true;
  c.armed_ns = pipeline::systemClockNs();
  c.generation = 0;  // re-join the current schedule at the first frame after arming
}

void LiveSchedule::disarmCamera(int camera) {
  {
    std::lock_guard lock(mutex_);
    CameraState& c = cameras_.at(static_cast<std::size_t>(camera));
    c.armed = false;
    ++c.stop_epoch;
    c.triggered.clear();
  }
  cv_.notify_all();
}

std::optional<pipeline::Frame> LiveSchedule::grab(int camera, std::chrono::milliseconds timeout) {
  const std::int64_t deadline = deadlineAfter(timeout);
  std::unique_lock lock(mutex_);
  CameraState& c = cameras_.at(static_cast<std::size_t>(camera));
  const std::uint64_t epoch = c.stop_epoch;
  while (true) {
    if (!c.armed || c.stop_epoch != epoch) return std::nullopt;
    const std::int64_t now = pipeline::systemClockNs();
    std::int64_t wake = deadline;
    if (!c.triggered.empty()) {  // software-triggered, ready after one frame interval
      const Exposure e = c.triggered.front();
      const std::int64_t ready = e.stamp_ns + std::llround(frame_interval_ns_);
      if (now >= ready) {
        c.triggered.erase(c.triggered.begin());
        pipeline::Frame frame;
        frame.frame_id = c.next_frame_id++;
        frame.stamp_ns = e.stamp_ns;
        frame.bit_depth = bit_depth_;
        ++counters_.frames_delivered;
        lock.unlock();
        std::uint64_t noise_seed = mix64(seed_ ^ mix64(frame.frame_id));
        if (camera > 0) noise_seed = mix64(noise_seed + static_cast<std::uint64_t>(camera));
        frame.image = render_(camera, e.pattern, e.frame, noise_seed);
        return frame;
      }
      wake = std::min(deadline, ready);
    } else if (generation_ != 0) {
      if (c.generation != generation_) {
        c.generation = generation_;
        c.next = std::max<std::int64_t>(0, lastStampAtOrBefore(c.armed_ns - 1) + 1);
        c.sequence_from = -1;
      }
      if (frameExists(c.next)) {
        const std::int64_t last_due = lastFrameAtOrBefore(now);
        const std::int64_t n = frames_per_sequence_;
        // A sequence whose first frame this camera delivered is delivered to
        // its end: drops start at a sequence start (or within a sequence the
        // camera joined late). Dropping the rest of a sequence in progress
        // would lose every sequence once rendering a frame takes longer
        // than about kLiveBufferDepth / n frame intervals.
        const bool in_sequence = c.next % n != 0 && c.sequence_from == c.next - c.next % n;
        if (last_due >= c.next && !in_sequence) {
          const std::int64_t behind = last_due - c.next + 1;
          if (behind > kLiveBufferDepth) {
            // Drop the oldest, up to the next sequence start.
            const std::int64_t keep_from = last_due - kLiveBufferDepth + 1;
            const std::int64_t dropped = (keep_from + n - 1) / n * n - c.next;
            c.next += dropped;
            c.next_frame_id += static_cast<std::uint64_t>(dropped);
            counters_.frames_dropped += static_cast<std::uint64_t>(dropped);
          }
        }
        // After a drop the next sequence may not be exposed yet, or may lie
        // beyond the end of the schedule.
        if (frameExists(c.next) && c.next <= last_due) {
          const std::int64_t j = c.next++;
          if (j % n == 0) c.sequence_from = j;
          pipeline::Frame frame;
          frame.frame_id = c.next_frame_id++;
          frame.stamp_ns = frameStamp(j);
          frame.bit_depth = bit_depth_;
          const std::size_t pattern = running_pattern_;
          const int pattern_frame = static_cast<int>(j % frames_per_sequence_);
          ++counters_.frames_delivered;
          lock.unlock();
          // Camera 0 keeps the single-camera seeds; further cameras draw their own noise.
          std::uint64_t noise_seed = mix64(seed_ ^ mix64(frame.frame_id));
          if (camera > 0) noise_seed = mix64(noise_seed + static_cast<std::uint64_t>(camera));
          frame.image = render_(camera, pattern, pattern_frame, noise_seed);
          return frame;
        }
        if (frameExists(c.next)) wake = std::min(deadline, frameStamp(c.next));
      }
    }
    if (now >= deadline) return std::nullopt;
    waitUntil(lock, wake);
  }
}

void LiveSchedule::triggerCamera(int camera) {
  {
    std::lock_guard lock(mutex_);
    CameraState& c = cameras_.at(static_cast<std::size_t>(camera));
    if (!c.armed) throw std::logic_error("camera: software trigger while not started");
    if (held_frame_ < 0)
      throw std::logic_error("camera: software trigger while the projector shows no pattern");
    c.triggered.push_back({pipeline::systemClockNs(), selected_, held_frame_});
  }
  cv_.notify_all();
}

// --- trigger source ---

std::optional<TriggerEvent> LiveSchedule::nextTrigger(std::chrono::milliseconds timeout) {
  const std::int64_t deadline = deadlineAfter(timeout);
  std::unique_lock lock(mutex_);
  const std::uint64_t epoch = trigger_stop_epoch_;
  while (true) {
    if (triggers_stopped_ || trigger_stop_epoch_ != epoch) return std::nullopt;
    const std::int64_t now = pipeline::systemClockNs();
    std::int64_t wake = deadline;
    if (generation_ != 0) {
      if (trigger_generation_ != generation_) {
        trigger_generation_ = generation_;
        trigger_next_ = 0;
      }
      const std::int64_t n = frames_per_sequence_;
      if (frameExists(trigger_next_ * n)) {
        const std::int64_t last_frame = lastFrameAtOrBefore(now);
        const std::int64_t last_due = last_frame < 0 ? -1 : last_frame / n;
        if (last_due >= trigger_next_) {
          const std::int64_t behind = last_due - trigger_next_ + 1;
          if (behind > kLiveBufferDepth) {  // drop the oldest
            const std::int64_t dropped = behind - kLiveBufferDepth;
            trigger_next_ += dropped;
            counters_.triggers_dropped += static_cast<std::uint64_t>(dropped);
          }
          const std::int64_t k = trigger_next_++;
          ++counters_.triggers_delivered;
          return TriggerEvent{frameStamp(k * n), static_cast<std::uint64_t>(k)};
        }
        wake = std::min(deadline, frameStamp(trigger_next_ * n));
      }
    }
    if (now >= deadline) return std::nullopt;
    waitUntil(lock, wake);
  }
}

void LiveSchedule::stopTriggers() {
  {
    std::lock_guard lock(mutex_);
    triggers_stopped_ = true;
    ++trigger_stop_epoch_;
  }
  cv_.notify_all();
}

SimCounters LiveSchedule::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

// --- adapters ---

namespace {

// Thread-safe (delegates to LiveSchedule).
class LiveCamera final : public Camera {
 public:
  LiveCamera(std::shared_ptr<LiveSchedule> schedule, int camera, std::string id, int width,
             int height)
      : schedule_(std::move(schedule)),
        camera_(camera),
        id_(std::move(id)),
        width_(width),
        height_(height) {}
  std::string id() const override { return id_; }
  int width() const override { return width_; }
  int height() const override { return height_; }
  void start() override { schedule_->armCamera(camera_); }
  void stop() override { schedule_->disarmCamera(camera_); }
  std::optional<pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    return schedule_->grab(camera_, timeout);
  }
  bool hasSoftwareTrigger() const override { return true; }
  void triggerSoftware() override { schedule_->triggerCamera(camera_); }

 private:
  const std::shared_ptr<LiveSchedule> schedule_;
  const int camera_;
  const std::string id_;
  const int width_, height_;
};

// Thread-safe (delegates to LiveSchedule).
class LiveProjector final : public Projector {
 public:
  LiveProjector(std::shared_ptr<LiveSchedule> schedule, std::string id)
      : schedule_(std::move(schedule)), id_(std::move(id)) {}
  std::string id() const override { return id_; }
  std::vector<ProjectorSequence> sequences() const override { return schedule_->sequences(); }
  void select(const std::string& name) override { schedule_->select(name); }
  void start(int count) override { schedule_->startProjector(count); }
  void stop() override { schedule_->stopProjector(); }
  bool canProjectSingle() const override { return true; }
  void projectSingle(int index) override { schedule_->projectSingle(index); }

 private:
  const std::shared_ptr<LiveSchedule> schedule_;
  const std::string id_;
};

// Thread-safe (delegates to LiveSchedule).
class LiveTriggerSource final : public TriggerSource {
 public:
  explicit LiveTriggerSource(std::shared_ptr<LiveSchedule> schedule)
      : schedule_(std::move(schedule)) {}
  std::optional<TriggerEvent> next(std::chrono::milliseconds timeout) override {
    return schedule_->nextTrigger(timeout);
  }
  void stop() override { schedule_->stopTriggers(); }

 private:
  const std::shared_ptr<LiveSchedule> schedule_;
};

}  // namespace

std::shared_ptr<Camera> makeLiveCamera(std::shared_ptr<LiveSchedule> schedule, int camera,
                                       std::string id, int width, int height) {
  return std::make_shared<LiveCamera>(std::move(schedule), camera, std::move(id), width, height);
}

std::shared_ptr<Projector> makeLiveProjector(std::shared_ptr<LiveSchedule> schedule,
                                             std::string id) {
  return std::make_shared<LiveProjector>(std::move(schedule), std::move(id));
}

std::shared_ptr<TriggerSource> makeLiveTriggerSource(std::shared_ptr<LiveSchedule> schedule) {
  return std::make_shared<LiveTriggerSource>(std::move(schedule));
}

}  // namespace sl::drivers::sim
