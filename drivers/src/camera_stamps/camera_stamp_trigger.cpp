#include "sl/drivers/camera_stamp_trigger.h"

#include <cmath>
#include <stdexcept>

namespace sl::drivers {

CameraStampSequencer::CameraStampSequencer(CameraStampTriggerConfig config) : config_(config) {}

void CameraStampSequencer::setSequence(int frames_per_sequence,
                                       pipeline::TimestampNs frame_period_ns) {
  if (frames_per_sequence < 1) throw std::invalid_argument("frames per sequence must be >= 1");
  if (frame_period_ns <= 0) throw std::invalid_argument("frame period must be > 0");
  frames_ = frames_per_sequence;
  period_ns_ = frame_period_ns;
  reset();
}

void CameraStampSequencer::reset() { last_stamp_.reset(); }

std::optional<TriggerEvent> CameraStampSequencer::push(pipeline::TimestampNs stamp) {
  if (frames_ == 0) return std::nullopt;
  const double steps =
      last_stamp_ ? static_cast<double>(stamp - *last_stamp_) / static_cast<double>(period_ns_) : 0;
  if (!last_stamp_ || stamp <= *last_stamp_ || steps > config_.max_gap_sequences * frames_) {
    index_ = 0;  // first frame, clock jump back, or the projector paused: a new sequence
  } else {
    index_ += std::max<long long>(1, std::llround(steps));  // dropped frames count too
  }
  last_stamp_ = stamp;
  if (index_ % frames_ != 0) return std::nullopt;
  return TriggerEvent{stamp - config_.offset_ns, sequences_++};
}

CameraStampTriggerSource::CameraStampTriggerSource(CameraStampTriggerConfig config)
    : config_(config), sequencer_(config) {}

void CameraStampTriggerSource::pushFrame(pipeline::TimestampNs stamp_ns) {
  std::lock_guard lock(mutex_);
  if (ignoring_) return;
  auto e = sequencer_.push(stamp_ns);
  if (!e) return;
  if (events_.size() >= config_.queue_depth) {
    events_.pop_front();
    ++dropped_;
  }
  events_.push_back(*e);
  cv_.notify_one();
}

void CameraStampTriggerSource::setSequence(int frames, pipeline::TimestampNs period_ns) {
  std::lock_guard lock(mutex_);
  sequencer_.setSequence(frames, period_ns);
}

void CameraStampTriggerSource::reset() {
  std::lock_guard lock(mutex_);
  sequencer_.reset();
  ignoring_ = false;
}

void CameraStampTriggerSource::ignoreFrames() {
  std::lock_guard lock(mutex_);
  ignoring_ = true;
}

std::optional<TriggerEvent> CameraStampTriggerSource::next(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  cv_.wait_for(lock, timeout, [&] { return stopped_ || !events_.empty(); });
  if (stopped_ || events_.empty()) return std::nullopt;
  const TriggerEvent e = events_.front();
  events_.pop_front();
  return e;
}

void CameraStampTriggerSource::stop() {
  std::lock_guard lock(mutex_);
  stopped_ = true;
  cv_.notify_all();
}

std::uint64_t CameraStampTriggerSource::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

StampTapCamera::StampTapCamera(std::shared_ptr<Camera> camera,
                               std::shared_ptr<CameraStampTriggerSource> source)
    : ForwardingCamera(std::move(camera)), source_(std::move(source)) {}

std::optional<Frame> StampTapCamera::grab(std::chrono::milliseconds timeout) {
  std::optional<Frame> frame = inner_->grab(timeout);
  if (frame) source_->pushFrame(frame->stamp_ns);
  return frame;
}

SequenceTapProjector::SequenceTapProjector(std::shared_ptr<Projector> projector,
                                           std::shared_ptr<CameraStampTriggerSource> source,
                                           std::map<std::string, Timing> timing)
    : ForwardingProjector(std::move(projector)), source_(std::move(source)), timing_(std::move(timing)) {}

void SequenceTapProjector::select(const std::string& name) {
  inner_->select(name);
  const auto it = timing_.find(name);
  if (it == timing_.end())
    throw std::invalid_argument("no frame timing for projector sequence '" + name + "'");
  source_->setSequence(it->second.frames, it->second.frame_period_ns);
}

void SequenceTapProjector::projectSingle(int index) {
  source_->ignoreFrames();
  inner_->projectSingle(index);
}

void SequenceTapProjector::start(int count) {
  source_->reset();
  inner_->start(count);
}

}  // namespace sl::drivers
