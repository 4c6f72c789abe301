// The daemon's configuration: one plain struct per component, parsed from
// YAML in one place (config.cpp). Components never see YAML.
#pragma once

#include <array>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "sl/daemon/adaptive.h"
#include "sl/daemon/aravis_config.h"
#include "sl/dds/cloud_layout.h"
#include "sl/client/commands.h"  // TriggerMode
#include "sl/files/config_error.h"
#include "sl/daemon/hardware_config.h"
#include "sl/drivers/replay.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/point_quality.h"
#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/motion_compensation.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/synchroniser.h"
#include "sl/pipeline/triangulator.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::dds::CloudLayout;
using ::sl::client::TriggerMode;

// Writer QoS of one published topic (`dds.qos.<topic>`). Keep-last writers
// never wait for a slow reader beyond their history: a reader that falls
// `depth` samples behind misses the oldest (see README "Slow readers").
struct TopicQos {
  bool reliable = true;
  int depth = 2;                // keep-last history, samples
  double max_blocking_s = 0.2;  // reliable: a write blocked longer is dropped (counted)
};

// What the daemon accepts of a request (`dds.requests`): longer strings or
// camera lists are refused with INVALID_OPTION; beyond its rate a sender's
// requests are not answered but counted (requests_rate_limited).
struct RequestLimits {
  std::size_t max_string = 256;   // client_id, pattern, recording, each camera id
  std::size_t max_cameras = 16;   // entries in cameras
  double rate_hz = 20;            // sustained requests per second per sender (DDS participant)
  double burst = 40;              // requests a sender may send at once
  // Rate buckets kept, one per sending DDS participant; further senders share one.
  std::size_t max_clients = 256;
};

// The sensor's frames on /tf_static (`dds.tf`, docs/ros2.md "tf"): parent ->
// base (the mount pose) -> each camera's optical frame; the first camera's
// optical frame -> the projector's.
struct TfConfig {
  bool publish = true;
  std::string parent_frame;  // "" = no mount transform: base_frame is a root
  std::string base_frame = "sl_base_link";  // REP 103 axes (x forward, z up) at the first camera
  std::string projector_frame = "sl_projector_optical_frame";
  std::array<double, 3> mount_xyz_m{0, 0, 0};       // base_frame's origin in parent_frame
  std::array<double, 4> mount_xyzw{0, 0, 0, 1};     // its rotation (unit quaternion x y z w)
};

struct DdsConfig {
  int domain_id = 0;
  std::string ns = "sl";              // topics are rt/<ns>/points, rq/<ns>/commandRequest, ...
  std::string frame_id = "sl_camera_optical_frame";
  bool publish_projector_maps = false;
  bool publish_image_sets = false;
  // Depth (32FC1, m) and shading (mono8) images and camera_info, ROS 2 types.
  bool publish_images = false;
  // What rt/<ns>/points carries: dds.points_decimation, dds.points_valid_only,
  // dds.points_normals, dds.points_confidence.
  CloudLayout points_layout;
  // dds.points_normal_step: the normals' central differences span +- this
  // many pixels (pipeline::organizedNormals).
  int points_normal_step = 3;
  // Clouds sent from their own memory instead of serialized by dds_write
  // (one 25 MB copy less per cloud; off with shared memory, see CloudWriter).
  bool points_zero_copy = true;
  double status_period_s = 1.0;
  // Per topic writer QoS (`dds.qos.points`, `.images` for depth, shading and
  // camera_info, `.projector_maps`, `.image_sets`).
  TopicQos points_qos{true, 4, 0.2};
  TopicQos images_qos{true, 2, 0.2};
  TopicQos maps_qos{true, 2, 0.2};
  TopicQos image_sets_qos{true, 2, 0.2};
  RequestLimits requests;
  TfConfig tf;
};

// Linear-motion compensation (paper section 2.4.2), off by default.
struct MotionConfig {
  bool enabled = false;
  pipeline::MotionCompensationOptions options;
};

// Software-trigger timing (`software_trigger:`).
struct SoftwareTriggerConfig {
  double settle_s = 0.01;       // wait after showing a pattern before triggering the cameras
  double grab_timeout_s = 1.0;  // longest wait for a triggered image (exposure + transfer)
};

struct RuntimeConfig {
  int queue_depth = 2;   // image sets / clouds waiting between stages (drop oldest)
  std::string default_pattern;  // selected at startup; first pattern if empty
  // Recordings requested over DDS go to <recording_root>/<name>; absolute
  // after loading (a relative key is resolved against $STATE_DIRECTORY
  // under systemd, else $XDG_DATA_HOME/sl-sensor or ~/.local/share/sl-sensor).
  std::string recording_root = "recordings";
  TriggerMode trigger = TriggerMode::kHardware;  // default of start requests
  // While scanning, a camera without frames, a trigger source without
  // triggers or a request without a published scan for this long makes the
  // status `degraded` with the cause (scan rate 0); it recovers by itself.
  double stall_timeout_s = 2.0;
  // Each stage thread touches, at start-up, the memory it recycles for
  // images and clouds, so that the first scans after START do not pay for
  // it (engine/memory_prefault.h): ~440 MB with config/sim.yaml, resident from
  // then on, and a few seconds more before the daemon is ready.
  bool prefault_memory = false;
  // last_error is dropped from the status this long after it was reported
  // (0 = kept until cleared by a recovery, a good reload or a new start).
  double last_error_hold_s = 300.0;
  // Recording quota (0 = no limit): bytes and image sets per recording, and
  // the free space a recording leaves on its file system.
  std::uint64_t recording_max_mb = 0;
  std::uint64_t recording_max_sets = 0;
  std::uint64_t recording_min_free_mb = 1024;
  // A cloud whose decode health is implausible (the pattern file does not
  // describe the projected frames: docs/decode-health.md) is counted and
  // not published, and a finite request ends with the cause; true publishes
  // it anyway (counted, the scan still degraded).
  bool publish_implausible = false;
};

// Which sensor the daemon runs (`sensor:`).
enum class SensorKind {
  kSim,       // the simulated sensor
  kHardware,  // cameras through Aravis, LightCrafter 4500, VersaVIS or camera-stamp triggers
  kFakeGige,  // the simulator behind Aravis' fake GigE Vision camera
  kReplay,    // a recording played back
};
const char* toString(SensorKind kind);  // as written in the config: sim, hardware, ...

struct DaemonConfig {
  std::string source_path;  // the file it was loaded from
  std::string source_text;  // its text, as loaded (served by COMMAND_GET_CONFIG)
  SensorKind sensor = SensorKind::kSim;
  drivers::SimConfig sim;
  HardwareConfig hardware;  // sensor: hardware (projector, trigger)
  drivers::ReplayConfig replay;  // sensor: replay (a recording played back)
  AravisSensorConfig aravis;  // sensor: hardware / fake_gige (cameras)
  // Calibration used by the triangulator. For the simulated sensor it
  // defaults to the simulated rig (perfect calibration).
  pipeline::CameraProjectorCalibration calibration;
  // Further cameras' calibrations against the projector, by camera id
  // (`calibrations:`); `calibration` above is the first camera's.
  std::map<std::string, pipeline::CameraProjectorCalibration> extra_calibrations;
  std::vector<pipeline::PatternSpec> patterns;
  // Cameras that triangulate each pattern (`patterns[].cameras`), by pattern
  // name; a pattern without an entry is triangulated by the first camera.
  std::map<std::string, std::vector<std::string>> pattern_cameras;
  // Optional camera whose view colours each pattern's clouds
  // (`patterns[].intensity_camera`): every point's intensity is the mean of
  // that camera's frames where the point projects into it.
  std::map<std::string, std::string> pattern_intensity_camera;
  pipeline::DecoderOptions decoder;
  pipeline::TriangulatorOptions triangulator;
  pipeline::SynchroniserOptions synchroniser;
  MotionConfig motion;
  // Adaptive scanning (`adaptive:`): off unless the section is present.
  AdaptiveConfig adaptive;
  SoftwareTriggerConfig software_trigger;
  DdsConfig dds;
  RuntimeConfig runtime;
  // The cameras' intensity noise for the depth sigma (`camera_noise:`,
  // docs/metrology.md); for sensor: sim, by default the simulator's
  // radiometry. Its bit depth is each scan's images'. Absent: unknown.
  std::optional<pipeline::CameraNoise> camera_noise;

  const pipeline::PatternSpec* findPattern(const std::string& name) const;
};

// The top-level keys (dotted for dds.*) whose values differ between two
// configs' texts, leaving out the keys a running daemon can take on a reload
// (SIGHUP): decoder, triangulator, motion_compensation, dds.status_period_s.
// Empty: `loaded` can be applied to a daemon running `running`.
std::vector<std::string> keysNeedingRestart(const DaemonConfig& running, const DaemonConfig& loaded);

// Loads and validates a config file. Throws ConfigError on a missing file,
// malformed YAML, an unknown or unused key, a wrong type or an invalid value.
DaemonConfig loadConfig(const std::string& path);
// Same, from a YAML string; `origin` names it in error messages.
DaemonConfig parseConfig(const std::string& yaml_text, const std::string& origin);

}  // namespace sl::daemon
