#include "recorder.h"

#include <chrono>

#include "sl/drivers/recording.h"

namespace sl::daemon {

Recorder::Recorder(std::size_t queue_depth) : queue_(queue_depth), thread_([this] { run(); }) {}

Recorder::~Recorder() {
  running_ = false;
  queue_.close();
  thread_.join();
}

void Recorder::start(const std::string& dir, const std::string& note) {
  drivers::createRecording(dir, note);
  const std::size_t existing = drivers::listRecordedSets(dir).size();
  std::lock_guard lock(mutex_);
  dir_ = dir;
  next_index_ = existing + 1;
  last_error_.clear();
  active_ = true;
}

void Recorder::stop() { active_ = false; }

void Recorder::record(std::shared_ptr<const pipeline::ImageSet> set) {
  if (!active_) return;
  Item item;
  {
    std::lock_guard lock(mutex_);
    item = {dir_, next_index_++, std::move(set)};
  }
  queue_.push(std::move(item));
}

std::string Recorder::lastError() const {
  std::lock_guard lock(mutex_);
  return last_error_;
}

void Recorder::run() {
  for (;;) {
    std::optional<Item> item = queue_.pop(std::chrono::milliseconds(200));
    if (!item) {
      if (!running_) return;  // closed and drained
      continue;
    }
    try {
      drivers::writeRecordedSet(item->dir, item->index, *item->set);
      ++written_;
    } catch (const std::exception& e) {
      std::lock_guard lock(mutex_);
      last_error_ = std::string("recording: ") + e.what();
      active_ = false;
    }
  }
}

}  // namespace sl::daemon
