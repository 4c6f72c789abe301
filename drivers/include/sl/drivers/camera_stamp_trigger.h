// Sequence start times without a trigger board: the projector's TRIG_OUT_1
// triggers the cameras once per pattern, so the first frame of each pattern
// sequence marks the sequence start. Its time comes from the camera's frame
// stamps and the projector's known frame period.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "sl/drivers/forwarding.h"
#include "sl/drivers/trigger_source.h"

namespace sl::drivers {

struct CameraStampTriggerConfig {
  // A gap between frames longer than this many sequence durations means the
  // projector was stopped: the next frame starts a new sequence. Shorter gaps
  // are dropped frames and advance the pattern count by round(gap / period).
  double max_gap_sequences = 2.0;
  // Trigger time = frame stamp - offset_ns (the camera stamps its exposure
  // start this long after the projector's trigger output).
  std::int64_t offset_ns = 0;
  std::size_t queue_depth = 64;  // undelivered events kept (oldest dropped)
};

// Synchronous and thread-compatible. Numbers the frames of a running
// sequence from their stamps: index += round(dt / frame period), so dropped
// frames keep the count right; every frame whose index is a multiple of the
// sequence length starts a sequence. The first frame after reset(), after a
// gap of more than max_gap_sequences or after a stamp going backwards is
// index 0. A dropped first frame of a sequence yields no event for it.
class CameraStampSequencer {
 public:
  explicit CameraStampSequencer(CameraStampTriggerConfig config = {});
  // Frames per sequence (>= 1) and the projector's frame period (ns, > 0);
  // resets the numbering. Throws std::invalid_argument.
  void setSequence(int frames_per_sequence, pipeline::TimestampNs frame_period_ns);
  void reset();
  // Feeds one frame stamp (ns); returns the trigger event when the frame
  // starts a sequence. Before setSequence() nothing is returned.
  std::optional<TriggerEvent> push(pipeline::TimestampNs frame_stamp_ns);

 private:
  CameraStampTriggerConfig config_;
  int frames_ = 0;
  pipeline::TimestampNs period_ns_ = 0;
  std::optional<pipeline::TimestampNs> last_stamp_;
  std::int64_t index_ = 0;
  std::uint64_t sequences_ = 0;
};

// A TriggerSource fed with frame stamps (by StampTapCamera). Thread-safe:
// pushFrame() from the camera thread, next() from the trigger thread,
// setSequence()/reset()/stop() from the control thread.
class CameraStampTriggerSource : public TriggerSource {
 public:
  explicit CameraStampTriggerSource(CameraStampTriggerConfig config = {});
  void pushFrame(pipeline::TimestampNs stamp_ns);
  void setSequence(int frames_per_sequence, pipeline::TimestampNs frame_period_ns);
  // Restarts the numbering; ends ignoreFrames().
  void reset();
  // Frames pushed from now until reset() are not sequence frames (the
  // projector holds single patterns for software triggering): ignored.
  void ignoreFrames();
  std::optional<TriggerEvent> next(std::chrono::milliseconds timeout) override;
  void stop() override;
  std::uint64_t dropped() const;  // events dropped because nobody called next()

 private:
  const CameraStampTriggerConfig config_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  CameraStampSequencer sequencer_;   // guarded by mutex_
  std::deque<TriggerEvent> events_;  // guarded by mutex_
  std::uint64_t dropped_ = 0;        // guarded by mutex_
  bool stopped_ = false;             // guarded by mutex_
  bool ignoring_ = false;            // guarded by mutex_
};

// Camera decorator: forwards everything (the software trigger too) and feeds
// each grabbed frame's stamp to the trigger source. Thread-safety as the
// wrapped camera.
class StampTapCamera : public ForwardingCamera {
 public:
  StampTapCamera(std::shared_ptr<Camera> camera, std::shared_ptr<CameraStampTriggerSource> source);
  std::optional<Frame> grab(std::chrono::milliseconds timeout) override;

 private:
  std::shared_ptr<CameraStampTriggerSource> source_;
};

// Projector decorator: tells the trigger source the length and frame period
// of the selected sequence and restarts its numbering on start(); while it
// holds single patterns (projectSingle, forwarded) the source ignores frames.
// Thread-safety as the wrapped projector.
class SequenceTapProjector : public ForwardingProjector {
 public:
  struct Timing {
    int frames = 0;
    pipeline::TimestampNs frame_period_ns = 0;
  };
  SequenceTapProjector(std::shared_ptr<Projector> projector,
                       std::shared_ptr<CameraStampTriggerSource> source,
                       std::map<std::string, Timing> timing);
  void select(const std::string& name) override;
  void start(int count) override;
  void projectSingle(int index) override;

 private:
  std::shared_ptr<CameraStampTriggerSource> source_;
  std::map<std::string, Timing> timing_;
};

}  // namespace sl::drivers
