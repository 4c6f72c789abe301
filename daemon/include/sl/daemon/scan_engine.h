// The daemon's pipeline: camera and trigger threads feed the synchroniser,
// whose image sets are decoded and triangulated on a processing thread and
// handed to an output thread. Stages are the synchronous classes of
// sl_pipeline; the threads and bounded queues live here.
//
//   camera thread(s) --frames---+
//                               +--> event queue -> sync thread -> set queue
//   trigger thread  --triggers--+                                     |
//                          output thread <- result queue <- processing thread
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "sl/daemon/config.h"
#include "sl/drivers/camera.h"
#include "sl/drivers/projector.h"
#include "sl/drivers/trigger_source.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

enum class ScanState { kIdle, kScanning, kError };
const char* toString(ScanState s);

// Outcome of a control request; `code` mirrors the DDS reply codes.
struct CommandResult {
  enum class Code { kOk, kUnknownPattern, kBusy, kInvalidCount, kInvalidCommand, kDeviceError,
                    kNotRunning };
  Code code = Code::kOk;
  std::string reason;
  bool accepted() const { return code == Code::kOk; }
};

struct EngineStatus {
  std::uint64_t version = 0;  // increases on every change worth publishing
  ScanState state = ScanState::kIdle;
  std::string pattern;
  std::uint64_t scans_done = 0;       // of the current / last request
  std::uint64_t scans_requested = 0;  // 0 = continuous
  double scan_rate_hz = 0;            // clouds per second, smoothed
  std::uint64_t frames_dropped = 0;   // frames lost before grouping (queue overflow, unmatched)
  std::uint64_t sets_dropped = 0;     // image sets or clouds dropped by a full queue
  std::uint64_t sets_incomplete = 0;  // sequences purged before all frames arrived
  std::string recording;              // recording in progress ("" = none)
  std::uint64_t sets_recorded = 0;    // since start-up
  std::string last_error;
};

// One scan's results, shared with the output callback.
// One camera's result of one scan (a pattern triangulated by two cameras
// gives two results with the same scan_index).
struct ScanResult {
  std::uint64_t scan_index = 0;  // 1-based within the current request
  std::string pattern;
  std::string camera_id;         // the triangulating camera
  std::shared_ptr<const pipeline::ImageSet> images;
  std::shared_ptr<const pipeline::ProjectorMaps> maps;
  std::shared_ptr<const pipeline::PointCloud> cloud;
};

struct EngineDevices {
  // All cameras of the sensor, in synchroniser order. Camera 0 uses
  // DaemonConfig::calibration, the others DaemonConfig::extra_calibrations.
  std::vector<std::shared_ptr<drivers::Camera>> cameras;
  std::shared_ptr<drivers::Projector> projector;
  std::shared_ptr<drivers::TriggerSource> trigger;
};

// Thread-safe: start/stop/selectPattern/status may be called from any thread.
// The output callback runs on the engine's output thread, one result at a
// time; it must not call back into the engine's control methods.
class ScanEngine {
 public:
  using OutputCallback = std::function<void(const ScanResult&)>;

  // Throws std::runtime_error when a pattern names a camera the devices lack
  // or one without a calibration.
  ScanEngine(const DaemonConfig& config, EngineDevices devices, OutputCallback output);
  ~ScanEngine();  // stops the projector and joins every thread
  ScanEngine(const ScanEngine&) = delete;
  ScanEngine& operator=(const ScanEngine&) = delete;

  // Starts `count` scans (0 = until stop) of `pattern` (empty = current);
  // with a `recording` name, the image sets are also written to
  // <runtime.recording_root>/<recording> until the request ends.
  CommandResult start(const std::string& pattern, int count, const std::string& recording = "");
  CommandResult stop();
  // Selects the pattern for the next start(); during a continuous scan it
  // switches at once (the sequence in progress is abandoned; no image set
  // ever mixes two patterns). Busy during a finite request.
  CommandResult selectPattern(const std::string& pattern);
  std::vector<std::string> patterns() const;
  const DaemonConfig& config() const;  // as loaded at start-up
  // Uses the run-time settings of `settings` (decoder, triangulator, motion
  // compensation) from the next image set on; its other parts are ignored.
  void applyRuntimeSettings(const DaemonConfig& settings);
  // Puts a message into the status topic's last_error.
  void reportError(const std::string& message);

  EngineStatus status() const;
  // True while every thread has made progress within the last `max_age`
  // (for the systemd watchdog).
  bool healthy() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::daemon
