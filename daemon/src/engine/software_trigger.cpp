#include "engine/software_trigger.h"

#include <algorithm>
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

bool SoftwareTrigger::acquire(const std::string& pattern, int frame_count,
                              const std::vector<std::size_t>& cameras,
                              const std::function<bool()>& cancelled,
                              pipeline::IndexedSynchroniser& grouping) {
  std::vector<std::size_t> used = cameras;
  if (used.empty())
    for (std::size_t c = 0; c < cameras_.size(); ++c) used.push_back(c);
  if (selected_ != pattern) {
    projector_->stop();
    projector_->select(pattern);
    selected_ = pattern;
  }
  const auto settle = std::chrono::duration<double>(config_.settle_s);
  for (int i = 0; i < frame_count; ++i) {
    if (cancelled()) return false;
    const pipeline::TimestampNs shown_ns = pipeline::systemClockNs();
    projector_->projectSingle(i);
    std::this_thread::sleep_for(settle);
    const pipeline::TimestampNs trigger_ns = pipeline::systemClockNs();
    if (i == 0) grouping.begin(pattern, frame_count, trigger_ns, used);
    for (std::size_t c : used) cameras_[c]->triggerSoftware();
    for (std::size_t c : used) {
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
      grouping.pushFrame(c, i, std::move(*frame));
    }
  }
  return true;
}

namespace {

std::vector<std::string> idsOf(const std::vector<std::shared_ptr<drivers::Camera>>& cameras) {
  std::vector<std::string> ids;
  for (const auto& c : cameras) ids.push_back(c->id());
  return ids;
}

}  // namespace

SoftwareRuns::SoftwareRuns(std::vector<std::shared_ptr<drivers::Camera>> cameras,
                           std::shared_ptr<drivers::Projector> projector, SoftwareTriggerConfig config)
    : trigger_(cameras, std::move(projector), config),
      grouping_(idsOf(cameras)),
      camera_ids_(idsOf(cameras)) {}

SoftwareRuns::Outcome SoftwareRuns::acquire(std::uint64_t generation, const std::string& pattern,
                                            int frame_count, const std::vector<std::string>& cameras,
                                            const std::function<bool()>& cancelled) {
  if (generation != generation_) {
    trigger_.stop();  // a new request: select its pattern afresh
    grouping_.startRun();
    generation_ = generation;
    acquired_ = 0;
    failures_ = 0;
  }
  Outcome out;
  try {
    std::vector<std::size_t> indices;
    for (const std::string& id : cameras) {
      const auto it = std::find(camera_ids_.begin(), camera_ids_.end(), id);
      if (it == camera_ids_.end())
        throw std::runtime_error("software trigger: no camera '" + id + "'");
      indices.push_back(static_cast<std::size_t>(it - camera_ids_.begin()));
    }
    std::sort(indices.begin(), indices.end());
    if (!trigger_.acquire(pattern, frame_count, indices, cancelled, grouping_)) {
      grouping_.abandon(false);  // stopped meanwhile
      return out;
    }
    auto sets = grouping_.takeCompleted();
    if (sets.size() != 1)
      throw std::logic_error("software trigger: a complete sequence gave " + std::to_string(sets.size()) +
                             " image sets");
    out.set = std::move(sets.front());
    out.frames = out.set->cameras.size() * static_cast<std::uint64_t>(frame_count);
    ++acquired_;
    failures_ = 0;
  } catch (const std::exception& e) {
    const bool fault = !cancelled();  // else stopped meanwhile: not a fault
    grouping_.abandon(fault);
    if (fault) {
      out.end_request = ++failures_ >= 3;
      out.fault = out.end_request ? std::string(e.what()) + " (3 sequences in a row failed; request ended)"
                                  : e.what();
    }
  }
  return out;
}

void SoftwareTrigger::stop() {
  projector_->stop();
  selected_.clear();
}

}  // namespace sl::daemon
