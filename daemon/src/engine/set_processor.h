// Per image set: motion compensation, decoding, triangulation by each of the
// pattern's cameras, colouring from an intensity camera. The processing
// thread's stage: synchronous, no DDS settings, errors returned as values.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "sl/dds/cloud_layout.h"
#include "sl/daemon/config.h"
#include "sl/pipeline/decode_health.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/motion_compensation.h"
#include "sl/pipeline/point_quality.h"
#include "sl/pipeline/scan_processor.h"
#include "sl/pipeline/triangulator.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::dds::PointQuality;

// What set processing needs, and nothing else.
struct ProcessingConfig {
  std::vector<pipeline::PatternSpec> patterns;
  pipeline::DecoderOptions decoder;
  pipeline::TriangulatorOptions triangulator;
  // Calibrations against the projector by camera id: one triangulator each.
  std::map<std::string, pipeline::CameraProjectorCalibration> calibrations;
  // Pattern -> the camera whose view colours its clouds (none: the
  // triangulating camera's own intensity).
  std::map<std::string, std::string> intensity_camera;
  bool motion_enabled = false;  // default of requests that leave it open
  pipeline::MotionCompensationOptions motion;
  bool keep_maps = false;  // return the projector maps (costs memory traffic)
  // Length unit of the clouds, in mm: 1 (millimetres, the pipeline's) or 1000
  // (metres, ROS's). The triangulators and the intensity transfer work on the
  // calibrations in that unit (pipeline::inUnits), so no pass converts the
  // points afterwards. Everything else here (triangulator depth limits
  // included) stays in mm.
  double cloud_unit_mm = 1.0;
  // Per-point quality of each cloud (CameraScan::quality): the expected depth
  // sigma (needs camera_noise and a phase-shift pattern; the maps are then
  // kept until it is computed) and the normals.
  bool depth_sigma = false;
  bool normals = false;
  int normal_step = 3;               // px, pipeline::organizedNormals
  float normal_max_jump_mm = 5.0f;   // a depth jump beyond this has no normal
  std::optional<pipeline::CameraNoise> camera_noise;  // bit depth: each scan's images'
};

// From the daemon's config for the sensor's cameras (`camera_ids`, in
// synchroniser order): the first uses `calibration`, the others their entry
// of `calibrations:` (if any); clouds in `cloud_unit_mm`; maps kept when
// `keep_maps` (the DDS edge publishes them); camera_noise from the config,
// no per-point quality (the caller sets it). No DDS settings are read.
ProcessingConfig processingConfigOf(const DaemonConfig& config, const std::vector<std::string>& camera_ids,
                                    double cloud_unit_mm = 1.0, bool keep_maps = false);

// One camera's result of one set.
struct CameraScan {
  std::string camera_id;  // the triangulating camera; also the cloud's frame_id
  int bit_depth = 8;      // of that camera's images
  std::shared_ptr<const pipeline::ProjectorMaps> maps;  // null unless keep_maps
  std::shared_ptr<const pipeline::PointCloud> cloud;    // cloud_unit_mm, that camera's optical frame
  // From the decoder's counts (pipeline::judgeDecodeTally: no modulation
  // per frequency).
  pipeline::DecodeHealth health;
  // Null unless depth_sigma or normals (depth sigma in cloud_unit_mm).
  std::shared_ptr<const PointQuality> quality;
};

struct SetOutcome {
  std::vector<CameraScan> scans;  // empty when `error` is set
  std::string error;              // names the stage and the sequence
  std::string warning;            // processed, but worth reporting
  bool ok() const { return error.empty(); }
};

// Thread-compatible: one processing thread owns it (its row workers are its
// own).
class SetProcessor {
 public:
  // Throws std::invalid_argument (from the pipeline stages) on a pattern or
  // calibration they reject, or depth_sigma without camera_noise.
  explicit SetProcessor(const ProcessingConfig& config);

  // Processes `set` for `cameras` (each must have images in the set);
  // motion compensation when `motion_compensation`. Never throws.
  SetOutcome process(const pipeline::ImageSet& set, const std::vector<std::string>& cameras,
                     bool motion_compensation);

  // Rebuilds the stages from new settings (a config reload). On an error the
  // old stages stay and the error is returned ("" = applied).
  std::string reconfigure(const ProcessingConfig& config);
  // reconfigure() with the run-time settings of a reloaded config (decoder,
  // triangulator, motion compensation); the rest of it is ignored.
  std::string applyRuntimeSettings(const DaemonConfig& settings);

  bool motionEnabled() const { return config_.motion_enabled; }

 private:
  struct Stages {
    std::map<std::string, pipeline::Decoder> decoders;            // by pattern
    std::map<std::string, pipeline::Triangulator> triangulators;  // by camera id
  };
  static Stages build(const ProcessingConfig& config);
  // Processes black frames once per camera, so that the first real scan
  // does not pay for its buffers' first page faults.
  void warmUp();
  std::shared_ptr<const PointQuality> pointQuality(const pipeline::PatternSpec& spec,
                                                   const std::string& camera_id, int bit_depth,
                                                   const pipeline::ProjectorMaps* maps,
                                                   const pipeline::PointCloud& cloud);
  std::shared_ptr<const pipeline::PointCloud> colouredCopy(const pipeline::ImageSet& set,
                                                           const std::string& camera_id,
                                                           const pipeline::PointCloud& cloud) const;

  ProcessingConfig loaded_;  // as given (config_ is in the clouds' unit)
  ProcessingConfig config_;
  Stages stages_;
  pipeline::MotionCompensator motion_;
  pipeline::ScanProcessor processor_;
};

// A reloaded config on its way to the processing thread, which applies it
// before its next set (SetProcessor::applyRuntimeSettings). Thread-safe.
class PendingSettings {
 public:
  void post(const DaemonConfig& settings);
  // The settings posted since the last take() (the latest of them), once;
  // a lock-free check when there are none.
  std::optional<DaemonConfig> take();

 private:
  std::mutex mutex_;
  std::optional<DaemonConfig> settings_;  // guarded by mutex_
  std::atomic<bool> pending_{false};
};

}  // namespace sl::daemon
