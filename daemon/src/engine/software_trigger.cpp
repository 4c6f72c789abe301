#include "software_trigger.h"

#include <stdexcept>
#include <thread>

namespace sl::daemon {

namespace {

std::chrono::milliseconds toMs(double seconds) {
  return std::chrono::milliseconds(static_cast<long long>(seconds * 1000 + 0.5));
}

}  // namespace

SoftwareTrigger::SoftwareTrigger(std::vector<std::shared_ptr<drivers::Camera>> cameras,
                                 std::shared_ptr<drivers::Projector> projector,
                                 SoftwareTriggerConfig config)
    : cameras_(std::move(cameras)), projector_(std::move(projector)), config_(config) {}

std::string SoftwareTrigger::unsupportedReason() const {
  if (!projector_->canProjectSingle())
    return "projector '" + projector_->id() + "' cannot show single patterns";
  for (const auto& camera : cameras_)
    if (!camera->hasSoftwareTrigger()) return "camera '" + camera->id() + "' has no software trigger";
  return "";
}

std::shared_ptr<const pipeline::ImageSet> SoftwareTrigger::acquire(
    const std::string& pattern, int frame_count, const std::function<bool()>& cancelled) {
  if (selected_ != pattern) {
    projector_->stop();
    projector_->select(pattern);
    selected_ = pattern;
  }
  auto set = std::make_shared<pipeline::ImageSet>();
  set->sequence_id = next_sequence_id_++;
  set->pattern_name = pattern;
  for (const auto& camera : cameras_) set->cameras.push_back({camera->id(), {}, {}, 8});
  const auto settle = std::chrono::duration<double>(config_.settle_s);
  for (int i = 0; i < frame_count; ++i) {
    if (cancelled()) return nullptr;
    const pipeline::TimestampNs shown_ns = pipeline::systemClockNs();
    projector_->projectSingle(i);
    std::this_thread::sleep_for(settle);
    const pipeline::TimestampNs trigger_ns = pipeline::systemClockNs();
    if (i == 0) set->trigger_stamp_ns = trigger_ns;
    for (const auto& camera : cameras_) camera->triggerSoftware();
    for (std::size_t c = 0; c < cameras_.size(); ++c) {
      const auto deadline = std::chrono::steady_clock::now() + toMs(config_.grab_timeout_s);
      std::optional<pipeline::Frame> frame;
      // Frames exposed before this pattern was shown are left over from an
      // earlier run: never ours.
      while (!frame && std::chrono::steady_clock::now() < deadline) {
        frame = cameras_[c]->grab(std::chrono::duration_cast<std::chrono::milliseconds>(
            deadline - std::chrono::steady_clock::now()));
        if (frame && frame->stamp_ns < shown_ns) {
          ++stale_frames_;
          frame.reset();
        }
      }
      if (!frame) {
        projector_->stop();
        selected_.clear();
        throw std::runtime_error("software trigger: camera '" + cameras_[c]->id() +
                                 "' delivered no image of pattern " + std::to_string(i) +
                                 " within " + std::to_string(config_.grab_timeout_s) + " s");
      }
      pipeline::CameraImages& images = set->cameras[c];
      if (i == 0) images.bit_depth = frame->bit_depth;
      images.frames.push_back(std::move(frame->image));
      images.stamps_ns.push_back(frame->stamp_ns);
    }
  }
  return set;
}

void SoftwareTrigger::stop() {
  projector_->stop();
  selected_.clear();
}

}  // namespace sl::daemon
