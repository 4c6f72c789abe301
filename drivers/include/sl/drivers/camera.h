// The camera interface implemented by the simulated, Aravis and replay
// cameras. A camera is pull-based: grab() blocks until the next frame or the
// timeout, the way arv_stream_timeout_pop_buffer does.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/types.h"

namespace sl::drivers {

using pipeline::Frame;

// Implementations say whether they are thread-safe; the daemon calls grab()
// from one thread per camera and start()/stop() from another.
class Camera {
 public:
  virtual ~Camera() = default;
  virtual std::string id() const = 0;
  virtual int width() const = 0;
  virtual int height() const = 0;
  virtual void start() = 0;  // begin delivering frames (on trigger)
  virtual void stop() = 0;   // wakes a blocked grab(), which returns nullopt
  // Next frame, or nullopt on timeout or when stopped. Throws on a device
  // fault that the caller cannot recover from by retrying.
  virtual std::optional<Frame> grab(std::chrono::milliseconds timeout) = 0;

  // Software trigger (setups without a trigger board): expose one frame now;
  // grab() delivers it, stamped with its exposure start. Only while started.
  // Cameras that cannot say false and throw std::logic_error.
  virtual bool hasSoftwareTrigger() const { return false; }
  virtual void triggerSoftware() {
    throw std::logic_error("camera '" + id() + "' has no software trigger");
  }
};

}  // namespace sl::drivers
