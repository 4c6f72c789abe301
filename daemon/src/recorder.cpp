#include "recorder.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <system_error>

#include "sl/daemon/log.h"
#include "sl/files/pattern_config.h"
#include "sl/drivers/recording.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::patternYaml;

namespace fs = std::filesystem;

namespace {

std::string megabytes(std::uint64_t bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f MB", bytes / 1e6);
  return text;
}

std::uint64_t rawBytes(const pipeline::ImageSet& set) {
  std::uint64_t bytes = 0;
  for (const auto& camera : set.cameras)
    for (const cv::Mat& frame : camera.frames)
      bytes += static_cast<std::uint64_t>(frame.total() * frame.elemSize());
  return bytes;
}

// Bytes of the files in one set folder (as written).
std::uint64_t folderBytes(const fs::path& dir) {
  std::uint64_t bytes = 0;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec))
    if (entry.is_regular_file(ec)) bytes += entry.file_size(ec);
  return bytes;
}

std::string setFolder(const std::string& dir, std::uint64_t index) {
  char name[32];
  std::snprintf(name, sizeof name, "set_%06llu", static_cast<unsigned long long>(index));
  return (fs::path(dir) / name).string();
}

}  // namespace

Recorder::Recorder(std::size_t queue_depth, RecordingQuota quota)
    : quota_(quota), queue_(queue_depth), thread_([this] { run(); }) {}

Recorder::~Recorder() {
  running_ = false;
  queue_.close();
  thread_.join();
}

void Recorder::start(const std::string& dir, const std::string& note,
                     const std::vector<pipeline::PatternSpec>& patterns) {
  std::map<std::string, std::string> pattern_yaml;
  for (const pipeline::PatternSpec& pattern : patterns) pattern_yaml[pattern.name] = patternYaml(pattern);
  drivers::createRecording(dir, note);
  if (quota_.min_free_bytes > 0) {
    std::error_code ec;
    const fs::space_info space = fs::space(dir, ec);
    if (!ec && space.available < quota_.min_free_bytes)
      throw std::runtime_error(dir + ": only " + megabytes(space.available) +
                               " free, below runtime.recording_min_free_mb (" +
                               megabytes(quota_.min_free_bytes) + ")");
  }
  const std::uint64_t next = drivers::nextRecordedSetIndex(dir);
  std::lock_guard lock(mutex_);
  dir_ = dir;
  pattern_yaml_ = std::move(pattern_yaml);
  next_index_ = next;
  ++epoch_;
  quota_reached_ = false;
  write_failed_ = false;
  recording_bytes_ = 0;
  recording_sets_ = 0;
  error_.message.clear();
  active_ = true;
}

void Recorder::stop() {
  std::lock_guard lock(mutex_);
  active_ = false;
  quota_reached_ = false;
  write_failed_ = false;
  ++epoch_;
}

void Recorder::record(std::shared_ptr<const pipeline::ImageSet> set) {
  if (quota_reached_) {
    ++over_quota_;
    return;
  }
  if (write_failed_) {
    ++not_written_;
    return;
  }
  if (!active_) return;
  Item item;
  {
    std::lock_guard lock(mutex_);
    if (write_failed_) {  // the writer failed since the check above
      ++not_written_;
      return;
    }
    const auto described = pattern_yaml_.find(set->pattern_name);
    item = {dir_, next_index_++, epoch_, std::move(set),
            described == pattern_yaml_.end() ? std::string() : described->second};
  }
  queue_.push(std::move(item));
}

Recorder::Error Recorder::lastError() const {
  std::lock_guard lock(mutex_);
  return error_;
}

std::string Recorder::quotaProblem(const std::string& dir, const pipeline::ImageSet& set) const {
  const std::uint64_t bytes = rawBytes(set);
  if (quota_.max_sets > 0 && recording_sets_ + 1 > quota_.max_sets)
    return "runtime.recording_max_sets (" + std::to_string(quota_.max_sets) + " sets) reached";
  if (quota_.max_bytes > 0 && recording_bytes_ + bytes > quota_.max_bytes)
    return "runtime.recording_max_mb (" + megabytes(quota_.max_bytes) + ") reached at " +
           megabytes(recording_bytes_);
  if (quota_.min_free_bytes > 0) {
    std::error_code ec;
    const fs::space_info space = fs::space(dir, ec);
    if (ec) return "cannot tell the free space of " + dir + ": " + ec.message();
    if (space.available < bytes || space.available - bytes < quota_.min_free_bytes)
      return "free space of " + dir + " (" + megabytes(space.available) +
             ") would fall below runtime.recording_min_free_mb (" +
             megabytes(quota_.min_free_bytes) + ")";
  }
  return "";
}

void Recorder::run() {
  for (;;) {
    std::optional<Item> item = queue_.pop(std::chrono::milliseconds(200));
    if (!item) {
      if (!running_) return;  // closed and drained
      continue;
    }
    std::string problem;
    {
      std::lock_guard lock(mutex_);
      if (item->epoch == failed_epoch_) {  // its recording failed: not tried again
        ++not_written_;
        continue;
      }
      if (item->epoch == quota_epoch_) problem = "quota";
      else if (item->dir == dir_) problem = quotaProblem(item->dir, *item->set);
      if (!problem.empty()) {
        ++over_quota_;
        if (problem != "quota") {
          quota_epoch_ = item->epoch;
          if (item->epoch == epoch_) {  // still recording: stop it
            quota_reached_ = true;
            active_ = false;
          }
          error_.message = "recording '" + fs::path(item->dir).filename().string() +
                           "' stopped after " + std::to_string(recording_sets_) + " sets (" +
                           megabytes(recording_bytes_) + "): " + problem;
          error_.stamp_ns = pipeline::systemClockNs();
          ++error_.count;
          logWarning(error_.message);
        }
        continue;
      }
    }
    try {
      drivers::writeRecordedSet(item->dir, item->index, *item->set, item->pattern_yaml);
      ++written_;
      const std::uint64_t bytes = folderBytes(setFolder(item->dir, item->index));
      std::lock_guard lock(mutex_);
      if (item->dir == dir_) {
        recording_bytes_ += bytes;
        ++recording_sets_;
      }
    } catch (const std::exception& e) {
      std::lock_guard lock(mutex_);
      ++not_written_;
      failed_epoch_ = item->epoch;
      if (item->epoch == epoch_) {  // still recording: stop it, count its further sets
        write_failed_ = true;
        active_ = false;
      }
      error_.message = "recording '" + fs::path(item->dir).filename().string() + "' stopped after " +
                       std::to_string(recording_sets_) + " sets: " + e.what();
      error_.stamp_ns = pipeline::systemClockNs();
      ++error_.count;
      logWarning(error_.message);
    }
  }
}

}  // namespace sl::daemon
