// The real-time side of the simulated sensor: the projector's trigger
// schedule, and the camera and trigger source that follow it.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <string>
#include <vector>

#include "sl/drivers/camera.h"
#include "sl/drivers/projector.h"
#include "sl/drivers/sim.h"
#include "sl/drivers/trigger_source.h"

namespace sl::drivers::sim {

// Renders, for camera `camera`, frame `frame` of pattern `pattern_index` with
// the given noise seed. Must be thread-safe (it is called without the
// schedule's lock held, possibly from several camera threads).
using RenderFunction = std::function<cv::Mat(int camera, std::size_t pattern_index, int frame,
                                             std::uint64_t noise_seed)>;

// Frames and triggers a slow consumer may fall behind by before the oldest
// are dropped (like the buffer pool of a camera driver). The camera then
// drops up to the next sequence start (whole sequences: what it delivers
// completes sequences, so a slow consumer loses scans in proportion). It
// decides so at a sequence start: a sequence it began to deliver is
// delivered to its end, however slowly the consumer (or the renderer) takes
// its frames.
inline constexpr std::int64_t kLiveBufferDepth = 8;
// Delay between Projector::start() and the first trigger.
inline constexpr std::int64_t kStartDelayNs = 20'000'000;

// The shared state of one simulated sensor's projector, camera and trigger
// source. Thread-safe: every member function locks mutex_; waits use cv_ and
// wake on stop, on a new schedule and on their timeout.
//
// A schedule (one Projector::start()) is a generation: sequence k of it is
// triggered at t0 + k * n * dt, its frame i exposed at t0 + (k * n + i) * dt,
// with t0 = start time + 20 ms, n the pattern's frame count and
// dt = 1 / camera_fps. It ends after `count` sequences or at stop(); frames
// and triggers stamped before the end are still delivered. A new schedule
// replaces the old one: what was not yet taken from the old one is discarded.
//
// Software triggering: projectSingle() holds one pattern (no schedule runs);
// triggerCamera() exposes a frame of it at once, which grab() delivers one
// frame interval later (exposure and readout at the camera's frame rate),
// before any scheduled frame.
class LiveSchedule {
 public:
  // camera_count cameras (>= 1) expose on the same schedule.
  LiveSchedule(std::vector<ProjectorSequence> sequences, double camera_fps, int bit_depth,
               std::uint64_t seed, RenderFunction render, int camera_count = 1);

  const std::vector<ProjectorSequence>& sequences() const { return sequences_; }

  // Projector.
  void select(const std::string& name);
  void startProjector(int count);
  void stopProjector();
  // Holds frame `index` of the selected sequence; std::logic_error while a
  // schedule runs, std::out_of_range on a bad index.
  void projectSingle(int index);

  // Camera `camera` (index < camera_count): frames exposed while armed, in
  // schedule order. Each camera has its own frame ids, counted from 0.
  void armCamera(int camera);
  void disarmCamera(int camera);
  std::optional<pipeline::Frame> grab(int camera, std::chrono::milliseconds timeout);
  // Software trigger of an armed camera while a pattern is held;
  // std::logic_error otherwise.
  void triggerCamera(int camera);

  // Trigger source.
  std::optional<TriggerEvent> nextTrigger(std::chrono::milliseconds timeout);
  void stopTriggers();

  SimCounters counters() const;

 private:
  static constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();

  // Exposure time (ns since epoch) of frame j of the current schedule.
  std::int64_t frameStamp(std::int64_t j) const;
  // Frames of the current schedule: j < frameLimit() (kNever when endless)
  // and frameStamp(j) < stop_ns_.
  std::int64_t frameLimit() const;
  bool frameExists(std::int64_t j) const;
  // Index of the last existing frame stamped at or before t_ns (-1 if none).
  std::int64_t lastFrameAtOrBefore(std::int64_t t_ns) const;
  bool runningLocked(std::int64_t now_ns) const;
  // Index of the last frame stamped at or before t_ns ignoring the end of the
  // schedule (-1 if none).
  std::int64_t lastStampAtOrBefore(std::int64_t t_ns) const;
  // Blocks until t_ns (system clock) or a notification.
  void waitUntil(std::unique_lock<std::mutex>& lock, std::int64_t t_ns);

  const std::vector<ProjectorSequence> sequences_;
  const double frame_interval_ns_;  // dt
  const int bit_depth_;
  const std::uint64_t seed_;
  const RenderFunction render_;

  mutable std::mutex mutex_;
  std::condition_variable cv_;

  // Projector, guarded by mutex_.
  std::size_t selected_ = 0;
  std::uint64_t generation_ = 0;  // 0: never started
  std::size_t running_pattern_ = 0;
  std::int64_t frames_per_sequence_ = 0;
  std::int64_t sequence_count_ = 0;  // 0: until stop
  std::int64_t t0_ns_ = 0;
  std::int64_t stop_ns_ = kNever;
  // projectSingle(): the held pattern (selected_) and frame; -1 = none.
  int held_frame_ = -1;

  // A software-triggered exposure waiting to be grabbed.
  struct Exposure {
    std::int64_t stamp_ns = 0;
    std::size_t pattern = 0;
    int frame = 0;
  };

  // Per camera, guarded by mutex_.
  struct CameraState {
    bool armed = false;
    std::int64_t armed_ns = 0;
    std::uint64_t generation = 0;  // schedule the camera follows (0: none yet)
    std::int64_t next = 0;         // next frame index of that schedule
    std::int64_t sequence_from = -1;  // first frame of the sequence being delivered (-1: none)
    std::uint64_t next_frame_id = 0;
    std::uint64_t stop_epoch = 0;  // bumped by disarmCamera() to wake grab()
    std::vector<Exposure> triggered;  // software triggers, oldest first
  };
  std::vector<CameraState> cameras_;

  // Trigger source, guarded by mutex_.
  std::uint64_t trigger_generation_ = 0;
  std::int64_t trigger_next_ = 0;  // next sequence index of that schedule
  bool triggers_stopped_ = false;  // until a new schedule starts
  std::uint64_t trigger_stop_epoch_ = 0;

  SimCounters counters_;  // guarded by mutex_
};

// Thin adapters handing out the schedule under the driver interfaces.
std::shared_ptr<Camera> makeLiveCamera(std::shared_ptr<LiveSchedule> schedule, int camera,
                                       std::string id, int width, int height);
std::shared_ptr<Projector> makeLiveProjector(std::shared_ptr<LiveSchedule> schedule,
                                             std::string id);
std::shared_ptr<TriggerSource> makeLiveTriggerSource(std::shared_ptr<LiveSchedule> schedule);

}  // namespace sl::drivers::sim
