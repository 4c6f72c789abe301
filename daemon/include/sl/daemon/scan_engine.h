// The daemon's pipeline: camera and trigger threads feed the grouping
// thread, whose image sets are decoded and triangulated on a processing
// thread and handed to an output thread. Stages are synchronous classes
// (sl_pipeline, daemon/src/engine/); the threads and bounded queues live in
// daemon/src/engine/scan_engine.cpp.
//
//   camera thread(s) --frames---+
//                               +--> input queue -> grouping thread -> set queue
//   trigger thread  --triggers--+         ^                                |
//                                         | schedule queue                 v
//   control thread: RequestControl -------+    output thread <- results <- processing thread
//
// The control thread starts delayed requests at their time, carries out
// pattern switches at sequence boundaries and, in software-trigger mode,
// acquires the image sets itself (projector stepped pattern by pattern, one
// grab per camera, grouped by pipeline::IndexedSynchroniser) into the set
// queue; the camera threads are parked meanwhile.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "sl/client/commands.h"
#include "sl/client/status_fields.h"
#include "sl/dds/cloud_layout.h"
#include "sl/daemon/config.h"
#include "sl/drivers/camera.h"
#include "sl/drivers/projector.h"
#include "sl/drivers/trigger_source.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::dds::PointQuality;
using ::sl::client::ScanState;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;

struct EngineStatus {
  std::uint64_t version = 0;  // increases on every change worth publishing
  ScanState state = ScanState::kIdle;
  std::string pattern;
  // The counters and measurements (sl/client/status_fields.h).
  SL_STATUS_ENGINE_FIELDS(SL_STATUS_DECLARE_FIELD)
  std::uint64_t sets_dropped = 0;     // sets_overflow + sets_not_recorded
  std::string recording;              // recording in progress ("" = none)
  std::string degraded_reason;        // kDegraded: what stalled, since when
  // The most recent error and when it was reported (system clock); cleared
  // when its cause recovers (a device delivers again, a reload succeeds), at
  // a new start, or runtime.last_error_hold_s after it was reported.
  std::string last_error;
  pipeline::TimestampNs last_error_ns = 0;
  // The current (or last) request's options as applied.
  TriggerMode trigger = TriggerMode::kHardware;
  std::vector<std::string> cameras;   // triangulating the current pattern
  bool motion_compensation = false;
  pipeline::TimestampNs start_at_ns = 0;  // kWaiting: when scanning starts
  // Adaptive scanning (DaemonConfig::adaptive): the mode of the running
  // continuous scan ("" = adaptive off, or no continuous scan) and why; the
  // mode switches since start-up are adaptive_switches (status_fields.h).
  std::string adaptive_mode;
  std::string adaptive_reason;
};

// One camera's result of one scan, shared with the output callback (a
// pattern triangulated by two cameras gives two results with the same
// scan_index).
struct ScanResult {
  std::uint64_t scan_index = 0;  // 1-based within the current request
  std::string pattern;
  std::string camera_id;         // the triangulating camera (also cloud->frame_id)
  int bit_depth = 8;             // of that camera's images (cloud intensities are its DN)
  // Null unless ResultContents::projector_maps: the processing then never
  // writes the maps out (pipeline::ScanProcessor::Keep::kCloud).
  std::shared_ptr<const pipeline::ProjectorMaps> maps;
  std::shared_ptr<const pipeline::PointCloud> cloud;  // the camera's optical frame, in cloud_unit_m
  double cloud_unit_m = 1e-3;  // metres per unit of the cloud's x, y, z (ResultContents::cloud_unit)
  // The image set the scan came from, as acquired (before motion
  // compensation).
  std::shared_ptr<const pipeline::ImageSet> images;
  // Null unless ResultContents asks for depth sigma or normals.
  std::shared_ptr<const PointQuality> quality;
};

struct EngineDevices {
  // All cameras of the sensor, in synchroniser order. Camera 0 uses
  // DaemonConfig::calibration, the others DaemonConfig::extra_calibrations.
  std::vector<std::shared_ptr<drivers::Camera>> cameras;
  std::shared_ptr<drivers::Projector> projector;
  std::shared_ptr<drivers::TriggerSource> trigger;
};

// Length unit of ScanResult::cloud: millimetres (the pipeline's, the
// default) or metres (ROS's: the clouds are triangulated in metres, so the
// DDS bridge writes them out without a pass over the points).
enum class CloudUnit { kMillimetres, kMetres };

// What the results carry, as their consumer (the DDS edge:
// DdsBridge::resultContents()) needs them.
struct ResultContents {
  CloudUnit cloud_unit = CloudUnit::kMillimetres;
  bool projector_maps = false;  // ScanResult::maps (they cost memory traffic)
  // The consumer keeps each ScanResult::cloud as it was written out, until
  // its readers are done with it (points sent from the cloud's own memory
  // by a reliable writer): the writer's history holds the processing
  // thread's clouds, not copies.
  bool keeps_clouds = false;
  // ScanResult::quality: the depth sigma (needs DaemonConfig::camera_noise)
  // and the normals (central differences +- normal_step px).
  bool depth_sigma = false;
  bool normals = false;
  int normal_step = 3;
};

// Thread-safe: start/stop/selectPattern/status may be called from any thread.
// The output callback runs on the engine's output thread, one result at a
// time; it must not call back into the engine's control methods.
class ScanEngine {
 public:
  using OutputCallback = std::function<void(const ScanResult&)>;

  // Throws std::runtime_error when a pattern names a camera the devices lack
  // or one without a calibration.
  ScanEngine(const DaemonConfig& config, EngineDevices devices, OutputCallback output,
             ResultContents contents = {});
  ~ScanEngine();  // stops the projector and joins every thread
  ScanEngine(const ScanEngine&) = delete;
  ScanEngine& operator=(const ScanEngine&) = delete;

  // Starts `count` scans (0 = until stop) of `pattern` (empty = current);
  // with a `recording` name, the image sets are also written to
  // <runtime.recording_root>/<recording> until the request ends. Rejected
  // (with a code and a reason naming the option) when scanning or waiting
  // (kBusy), on a negative count, an unknown pattern, an invalid option, or
  // a trigger mode the devices cannot do (kUnsupported).
  CommandResult start(const StartRequest& request);
  CommandResult start(const std::string& pattern, int count, const std::string& recording = "");
  // Ends a scan, or cancels a start that is still waiting for its time.
  CommandResult stop();
  // Selects the pattern for the next start(); during a continuous scan it
  // switches at the next sequence boundary (the sequence in progress
  // completes with the old pattern; no image set ever mixes two patterns).
  // Busy during a finite request.
  CommandResult selectPattern(const std::string& pattern);
  std::vector<std::string> patterns() const;
  const DaemonConfig& config() const;  // as loaded at start-up
  // Uses the run-time settings of `settings` (decoder, triangulator, motion
  // compensation) from the next image set on; its other parts are ignored.
  void applyRuntimeSettings(const DaemonConfig& settings);
  // Puts a message into the status topic's last_error. `source` names what
  // it came from, so that clearError(source) removes it once that recovered
  // (e.g. "reload").
  void reportError(const std::string& message, const std::string& source = "");
  void clearError(const std::string& source);
  // The robot's latest velocity (adaptive scanning; ignored unless
  // DaemonConfig::adaptive is enabled). While a continuous scan runs, the
  // engine switches pattern and motion compensation as the policy decides
  // (sl/daemon/adaptive_policy.h), through selectPattern's path.
  void setVelocity(const VelocitySample& velocity);

  EngineStatus status() const;
  // True while every thread has made progress within the last `max_age`
  // (for the systemd watchdog).
  bool healthy() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::daemon
