#include "sl/pipeline/indexed_synchroniser.h"

#include <stdexcept>

namespace sl::pipeline {

IndexedSynchroniser::IndexedSynchroniser(std::vector<std::string> camera_ids)
    : camera_ids_(std::move(camera_ids)) {
  if (camera_ids_.empty()) throw std::invalid_argument("IndexedSynchroniser: no cameras");
}

void IndexedSynchroniser::startRun() {
  abandon(false);
  next_sequence_id_ = 0;
}

void IndexedSynchroniser::begin(std::string pattern, int frame_count, TimestampNs trigger_stamp_ns,
                                std::vector<std::size_t> cameras) {
  if (frame_count < 1) throw std::invalid_argument("IndexedSynchroniser: frame_count must be >= 1");
  std::vector<bool> expected(camera_ids_.size(), cameras.empty());
  for (std::size_t c : cameras) {
    if (c >= camera_ids_.size())
      throw std::out_of_range("IndexedSynchroniser: camera index " + std::to_string(c) +
                              " but only " + std::to_string(camera_ids_.size()) + " cameras");
    expected[c] = true;
  }
  abandon(true);
  open_ = std::make_shared<ImageSet>();
  open_->pattern_name = std::move(pattern);
  open_->trigger_stamp_ns = trigger_stamp_ns;
  frames_.assign(camera_ids_.size(), std::vector<std::optional<Frame>>(frame_count));
  expected_ = std::move(expected);
  missing_ = 0;
  for (bool e : expected_) missing_ += e ? static_cast<std::size_t>(frame_count) : 0;
}

void IndexedSynchroniser::pushFrame(std::size_t camera_index, int index, Frame frame) {
  if (camera_index >= camera_ids_.size())
    throw std::out_of_range("IndexedSynchroniser: camera index " + std::to_string(camera_index) +
                            " but only " + std::to_string(camera_ids_.size()) + " cameras");
  if (!open_ || !expected_[camera_index] || index < 0 ||
      index >= static_cast<int>(frames_[camera_index].size()) || frames_[camera_index][index]) {
    ++counters_.frames_unmatched;
    return;
  }
  frames_[camera_index][index] = std::move(frame);
  if (--missing_ > 0) return;
  open_->sequence_id = next_sequence_id_++;
  for (std::size_t c = 0; c < camera_ids_.size(); ++c) {
    if (!expected_[c]) continue;
    CameraImages& images = open_->cameras.emplace_back();
    images.camera_id = camera_ids_[c];
    images.bit_depth = frames_[c][0]->bit_depth;
    for (auto& f : frames_[c]) {
      images.frames.push_back(std::move(f->image));
      images.stamps_ns.push_back(f->stamp_ns);
    }
  }
  completed_.push_back(std::move(open_));
  open_.reset();
  frames_.clear();
  ++counters_.sets_completed;
}

void IndexedSynchroniser::abandon(bool count) {
  if (!open_) return;
  if (count) {
    ++counters_.triggers_incomplete;
    for (const auto& camera : frames_)
      for (const auto& f : camera) counters_.frames_unmatched += f.has_value();
  }
  open_.reset();
  frames_.clear();
  missing_ = 0;
}

std::vector<std::shared_ptr<const ImageSet>> IndexedSynchroniser::takeCompleted() {
  std::vector<std::shared_ptr<const ImageSet>> out;
  out.swap(completed_);
  return out;
}

}  // namespace sl::pipeline
