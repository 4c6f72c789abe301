#include "sl/daemon/config.h"
#include "sim_config_yaml.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <set>
#include <sstream>

#include <Eigen/Geometry>

#include "sl/files/calibration_yaml.h"
#include "hardware_config_yaml.h"
#include "sl/files/pattern_config_yaml.h"
#include "sl/files/calibration_io.h"
#include "sl/pipeline/projector_response.h"
#include "aravis_config_yaml.h"
#include "sl/drivers/recording.h"
#include "tf_tree.h"
#include "sl/files/yaml_reader.h"
#include "sl/files/input_file.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::ConfigError;
using ::sl::files::InputKind;
using ::sl::client::TriggerMode;
using ::sl::files::YamlMap;
using ::sl::files::loadCalibration;
using ::sl::files::loadOpenCvCalibration;
using ::sl::files::parseInputYaml;
using ::sl::files::parseOpenCvCalibrationKeys;
using ::sl::files::readInputFile;

namespace {

void parsePatterns(const YamlMap& root, const pipeline::PinholeModel& projector,
                   const std::filesystem::path& base_dir, DaemonConfig& config) {
  std::set<std::string> names;
  for (const YamlMap& m : root.listOfMaps("patterns")) {
    // `cameras`: which cameras triangulate this pattern (a daemon setting, so
    // read here, before the pattern description itself).
    std::vector<std::string> cameras;
    if (m.has("cameras")) {
      const YAML::Node list = m.raw("cameras");
      if (!list.IsSequence() || list.size() == 0)
        m.fail("cameras", "expected a non-empty list of camera ids");
      for (const auto& id : list) {
        if (!id.IsScalar() || id.Scalar().empty()) m.fail("cameras", "camera ids must be names");
        cameras.push_back(id.Scalar());
      }
    }
    // `intensity_camera`: a camera whose view gives the clouds' intensity.
    const std::string intensity_camera = m.get<std::string>("intensity_camera", "");
    pipeline::PatternSpec p = parsePattern(m, "", &projector, base_dir.string());
    if (!names.insert(p.name).second) m.fail("name", "duplicate pattern name '" + p.name + "'");
    if (!cameras.empty()) config.pattern_cameras[p.name] = cameras;
    if (!intensity_camera.empty()) config.pattern_intensity_camera[p.name] = intensity_camera;
    config.patterns.push_back(p);
  }
}

// `calibrations:` {camera_id: path, ...} for cameras after the first.
void parseExtraCalibrations(const YamlMap& root, const std::filesystem::path& base_dir,
                            DaemonConfig& config) {
  if (!root.has("calibrations")) return;
  const YAML::Node node = root.raw("calibrations");
  if (!node.IsMap()) root.fail("calibrations", "expected a map of camera id: calibration file");
  for (const auto& entry : node) {
    const std::string id = entry.first.as<std::string>();
    if (!entry.second.IsScalar())
      root.fail("calibrations", "the calibration of camera '" + id + "' must be a file path");
    std::filesystem::path path(entry.second.Scalar());
    if (path.is_relative()) path = base_dir / path;
    if (!std::filesystem::is_regular_file(path))
      root.fail("calibrations", "cannot read calibration file '" + path.string() + "' of camera '" +
                                    id + "': " +
                                    (std::filesystem::is_directory(path) ? "a directory"
                                     : std::filesystem::exists(path)      ? "not a regular file"
                                                                          : "no such file"));
    config.extra_calibrations[id] = loadCalibration(path.string()).calibration;
  }
}

void parseDecoder(const YamlMap& m, pipeline::DecoderOptions& d) {
  // A number, or `auto` (the default): derived from each pattern
  // (pipeline::derivedMinModulation).
  if (m.has("min_modulation")) {
    const YAML::Node min_modulation = m.raw("min_modulation");
    if (min_modulation.IsScalar() && min_modulation.Scalar() == "auto")
      d.min_modulation = pipeline::kDerivedMinModulation;
    else
      d.min_modulation = static_cast<float>(nonNegative(m, "min_modulation", 0.0));
  }
  d.reject_saturated = m.get<bool>("reject_saturated", d.reject_saturated);
  d.max_unwrap_error = static_cast<float>(positive(m, "max_unwrap_error", d.max_unwrap_error));
  if (d.max_unwrap_error >= 0.5f) m.fail("max_unwrap_error", "must be < 0.5 (periods)");
  // The projector's response, compensated in decoding (projector_response.h):
  // `projector_gamma: G` (R = L^G) or `projector_response: [R(0), ..., R(1)]`.
  if (m.has("projector_gamma") && m.has("projector_response"))
    m.fail("projector_response", "give one of projector_gamma and projector_response");
  try {
    if (m.has("projector_gamma")) {
      const double gamma = positive(m, "projector_gamma", 1.0);
      if (gamma != 1.0) d.projector_response = pipeline::gammaResponse(gamma);
    } else if (m.has("projector_response")) {
      for (double v : m.get<std::vector<double>>("projector_response"))
        d.projector_response.push_back(static_cast<float>(v));
      pipeline::validateProjectorResponse(d.projector_response);
    }
  } catch (const std::invalid_argument& e) {
    m.fail(m.has("projector_gamma") ? "projector_gamma" : "projector_response", e.what());
  }
  m.done();
}

void parseTriangulator(const YamlMap& m, pipeline::TriangulatorOptions& t) {
  const std::string use = m.get<std::string>("use", "best");
  using Use = pipeline::TriangulatorOptions::Use;
  if (use == "best") t.use = Use::kBest;
  else if (use == "columns") t.use = Use::kColumns;
  else if (use == "rows") t.use = Use::kRows;
  else m.fail("use", "must be best, columns or rows, not '" + use + "'");
  t.min_depth_mm = static_cast<float>(positive(m, "min_depth_mm", t.min_depth_mm));
  t.max_depth_mm = static_cast<float>(positive(m, "max_depth_mm", t.max_depth_mm));
  if (t.max_depth_mm <= t.min_depth_mm) m.fail("max_depth_mm", "must be > min_depth_mm");
  t.projector_distortion_iterations =
      m.get<int>("projector_distortion_iterations", t.projector_distortion_iterations);
  if (t.projector_distortion_iterations < 0 || t.projector_distortion_iterations > 10)
    m.fail("projector_distortion_iterations", "must be in 0..10");
  m.done();
}

void parseSynchroniser(const YamlMap& m, double camera_fps, pipeline::SynchroniserOptions& s) {
  s.image_interval_ns = static_cast<pipeline::TimestampNs>(std::llround(1e9 / camera_fps));
  s.tolerance_lower = nonNegative(m, "tolerance_lower", s.tolerance_lower);
  s.tolerance_upper = nonNegative(m, "tolerance_upper", s.tolerance_upper);
  if (s.tolerance_lower + s.tolerance_upper >= 1.0)
    m.fail("tolerance_upper", "tolerance_lower + tolerance_upper must be < 1 (image intervals)");
  s.max_age_ns = static_cast<pipeline::TimestampNs>(
      1e9 * positive(m, "max_age_s", s.max_age_ns / 1e9));
  m.done();
}

void parseTopicQos(const YamlMap& m, TopicQos& q) {
  const std::string reliability = m.get<std::string>("reliability", q.reliable ? "reliable" : "best_effort");
  if (reliability != "reliable" && reliability != "best_effort")
    m.fail("reliability", "must be reliable or best_effort, not '" + reliability + "'");
  q.reliable = reliability == "reliable";
  q.depth = m.get<int>("depth", q.depth);
  if (q.depth < 1 || q.depth > 64) m.fail("depth", "must be in 1..64");
  q.max_blocking_s = nonNegative(m, "max_blocking_s", q.max_blocking_s);
  if (q.max_blocking_s > 10) m.fail("max_blocking_s", "must be at most 10 s");
  m.done();
}

void parseDds(const YamlMap& m, DdsConfig& d, const std::filesystem::path& base_dir) {
  d.domain_id = m.get<int>("domain_id", d.domain_id);
  if (d.domain_id < 0 || d.domain_id > 232) m.fail("domain_id", "must be in 0..232");
  d.ns = m.get<std::string>("namespace", d.ns);
  if (d.ns.empty() || d.ns.find_first_not_of(
                          "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_/") !=
                          std::string::npos || d.ns.front() == '/' || d.ns.back() == '/' ||
      d.ns.size() > 128)  // topic names stay far below DDS's limits
    m.fail("namespace", "must be 1..128 letters, digits, '_' or inner '/'");
  d.frame_id = m.get<std::string>("frame_id", d.frame_id);
  if (d.frame_id.empty() || d.frame_id.size() > 128)
    m.fail("frame_id", "must be 1..128 characters");
  d.publish_projector_maps = m.get<bool>("publish_projector_maps", d.publish_projector_maps);
  d.publish_image_sets = m.get<bool>("publish_image_sets", d.publish_image_sets);
  d.publish_images = m.get<bool>("publish_images", d.publish_images);
  d.points_layout.decimation = m.get<int>("points_decimation", d.points_layout.decimation);
  if (d.points_layout.decimation < 1 || d.points_layout.decimation > 16)
    m.fail("points_decimation", "must be 1..16 (1 = every pixel)");
  d.points_layout.valid_only = m.get<bool>("points_valid_only", d.points_layout.valid_only);
  d.points_layout.normals = m.get<bool>("points_normals", d.points_layout.normals);
  d.points_layout.confidence = m.get<bool>("points_confidence", d.points_layout.confidence);
  d.points_normal_step = m.get<int>("points_normal_step", d.points_normal_step);
  if (d.points_normal_step < 1 || d.points_normal_step > 32)
    m.fail("points_normal_step", "must be 1..32 pixels");
  d.points_zero_copy = m.get<bool>("points_zero_copy", d.points_zero_copy);
  d.status_period_s = positive(m, "status_period_s", d.status_period_s);
  const YamlMap qos = m.optionalMap("qos");
  parseTopicQos(qos.optionalMap("points"), d.points_qos);
  parseTopicQos(qos.optionalMap("images"), d.images_qos);
  parseTopicQos(qos.optionalMap("projector_maps"), d.maps_qos);
  parseTopicQos(qos.optionalMap("image_sets"), d.image_sets_qos);
  qos.done();
  const YamlMap requests = m.optionalMap("requests");
  RequestLimits& r = d.requests;
  auto whole = [&](const char* key, std::size_t fallback, std::size_t lo, std::size_t hi) {
    const int v = requests.get<int>(key, static_cast<int>(fallback));
    if (v < static_cast<int>(lo) || v > static_cast<int>(hi))
      requests.fail(key, "must be in " + std::to_string(lo) + ".." + std::to_string(hi));
    return static_cast<std::size_t>(v);
  };
  r.max_string = whole("max_string", r.max_string, 16, 65536);
  r.max_cameras = whole("max_cameras", r.max_cameras, 1, 256);
  r.max_clients = whole("max_clients", r.max_clients, 1, 65536);
  r.rate_hz = requests.get<double>("rate_hz", r.rate_hz);
  if (!(r.rate_hz >= 0.1 && r.rate_hz <= 10000)) requests.fail("rate_hz", "must be in [0.1, 10000] requests/s");
  r.burst = requests.get<double>("burst", r.burst);
  if (!(r.burst >= 1 && r.burst <= 100000)) requests.fail("burst", "must be in [1, 100000] requests");
  requests.done();
  parseTfConfig(m.optionalMap("tf"), d.tf, base_dir);
  m.done();
}

// `camera_noise:` (8-bit DN), by default the simulator's radiometry for
// sensor: sim (its analog gain scales both noises, drivers/sim.h); required
// by dds.points_confidence.
void parseCameraNoise(const YamlMap& root, DaemonConfig& config) {
  if (root.has("camera_noise")) {
    const YamlMap m = root.optionalMap("camera_noise");
    pipeline::CameraNoise noise;
    noise.gain_dn_per_electron = nonNegative(m, "gain_dn_per_electron", noise.gain_dn_per_electron);
    noise.read_noise_dn = nonNegative(m, "read_noise_dn", noise.read_noise_dn);
    m.done();
    config.camera_noise = noise;
  } else if (config.sensor == SensorKind::kSim) {
    pipeline::CameraNoise noise;
    noise.gain_dn_per_electron = config.sim.analog_gain * config.sim.gain_dn_per_electron;
    noise.read_noise_dn = config.sim.analog_gain * config.sim.read_noise_dn;
    config.camera_noise = noise;
  }
  // The phase-noise model covers the phase-shift families only
  // (pipeline/point_quality.h).
  if (config.dds.points_layout.confidence)
    for (const pipeline::PatternSpec& p : config.patterns)
      if (p.family == pipeline::PatternFamily::kGrayCode || p.family == pipeline::PatternFamily::kMicroPhaseShift)
        root.fail("dds", "points_confidence: pattern '" + p.name +
                             "' has no phase-noise model (Gray code or micro phase shift)");
  if (config.dds.points_layout.confidence && !config.camera_noise)
    root.fail("camera_noise",
              "needed by dds.points_confidence: the camera's gain_dn_per_electron and read_noise_dn "
              "(8-bit DN; docs/metrology.md \"Per-point quality\")");
}

void parseMotion(const YamlMap& m, MotionConfig& motion) {
  motion.enabled = m.get<bool>("enabled", motion.enabled);
  auto& o = motion.options;
  const std::string axis = m.get<std::string>("axis", "x");
  if (axis == "x") o.axis = pipeline::MotionCompensationOptions::Axis::kX;
  else if (axis == "y") o.axis = pipeline::MotionCompensationOptions::Axis::kY;
  else m.fail("axis", "must be x or y (the image axis the scene moves along), not '" + axis + "'");
  o.reference_frame = m.get<int>("reference_frame", o.reference_frame);
  if (o.reference_frame < -1) m.fail("reference_frame", "must be -1 (middle frame) or a frame index");
  o.subsample = m.get<int>("subsample", o.subsample);
  if (o.subsample != 1 && o.subsample != 2 && o.subsample != 4)
    m.fail("subsample", "must be 1, 2 or 4");
  o.window = m.get<bool>("window", o.window);
  o.max_shift_px = positive(m, "max_shift_px", o.max_shift_px);
  o.max_deviation_px = m.get<double>("max_deviation_px", o.max_deviation_px);
  if (!(o.max_deviation_px >= 0 && o.max_deviation_px <= 1000))
    m.fail("max_deviation_px", "must be in [0, 1000] px (0: no consistency check)");
  m.done();
}

// `adaptive:` (issue 33 item 4, docs/formats.md "Adaptive scanning"): after
// the patterns and motion_compensation, which its modes refer to.
void parseAdaptive(const YamlMap& m, const DaemonConfig& config, AdaptiveConfig& a) {
  std::string topic = m.get<std::string>("velocity_topic");
  if (!topic.empty() && topic.front() == '/') topic.erase(0, 1);
  if (topic.empty() || topic.size() > 128 || topic.back() == '/' ||
      topic.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_/") !=
          std::string::npos)
    m.fail("velocity_topic", "must be a ROS 2 topic name: 1..128 letters, digits, '_' or inner '/'");
  a.velocity_topic = topic;
  a.frame_id = m.get<std::string>("frame_id", a.frame_id);
  auto inRange = [&](const char* key, double fallback, double lo, double hi, const char* unit) {
    const double v = m.get<double>(key, fallback);
    if (!(v >= lo && v <= hi))
      m.fail(key, "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "] " + unit);
    return v;
  };
  a.velocity_timeout_s = inRange("velocity_timeout_s", a.velocity_timeout_s, 0.01, 60, "s");
  a.static_speed_m_s = inRange("static_speed_m_s", a.static_speed_m_s, 0, 10, "m/s");
  a.static_angular_rad_s = inRange("static_angular_rad_s", a.static_angular_rad_s, 0, 10, "rad/s");
  a.max_speed_m_s = inRange("max_speed_m_s", a.max_speed_m_s, 0, 10, "m/s");
  a.max_angular_rad_s = inRange("max_angular_rad_s", a.max_angular_rad_s, 0, 10, "rad/s");
  a.max_off_axis = inRange("max_off_axis", a.max_off_axis, 0, 1, "(fraction of the speed)");
  a.hysteresis = inRange("hysteresis", a.hysteresis, 0, 1, "(fraction)");
  a.min_dwell_s = inRange("min_dwell_s", a.min_dwell_s, 0, 600, "s");
  if (!(a.static_speed_m_s < a.max_speed_m_s))
    m.fail("max_speed_m_s", "must be above static_speed_m_s");
  if (!(a.static_angular_rad_s <= a.max_angular_rad_s))
    m.fail("max_angular_rad_s", "must be at least static_angular_rad_s");
  auto modeNamed = [&](const std::string& name) -> std::optional<AdaptiveMode> {
    for (std::size_t i = 0; i < kAdaptiveModes; ++i)
      if (name == toString(static_cast<AdaptiveMode>(i))) return static_cast<AdaptiveMode>(i);
    return std::nullopt;
  };
  const std::string safe = m.get<std::string>("safe_mode", toString(a.safe_mode));
  const std::optional<AdaptiveMode> safe_mode = modeNamed(safe);
  if (!safe_mode) m.fail("safe_mode", "must be static, linear_x, linear_y or moving, not '" + safe + "'");
  a.safe_mode = *safe_mode;
  // Every mode says what to do: a pattern (and compensation), or pause.
  const YamlMap modes = m.map("modes");
  for (std::size_t i = 0; i < kAdaptiveModes; ++i) {
    const auto mode = static_cast<AdaptiveMode>(i);
    const YamlMap entry = modes.map(toString(mode));
    AdaptiveAction& action = a.actions[i];
    action.pause = entry.get<bool>("pause", false);
    if (action.pause) {
      if (entry.has("pattern") || entry.has("motion_compensation"))
        entry.fail("pause", "a paused mode has no pattern or motion_compensation");
    } else {
      action.pattern = entry.get<std::string>("pattern");
      if (!config.findPattern(action.pattern))
        entry.fail("pattern", "no pattern named '" + action.pattern + "'");
      action.motion_compensation = entry.get<bool>("motion_compensation", false);
      // The compensation axis is motion_compensation.axis for every mode.
      using Axis = pipeline::MotionCompensationOptions::Axis;
      const Axis axis = config.motion.options.axis;
      if (action.motion_compensation &&
          ((mode == AdaptiveMode::kLinearX && axis != Axis::kX) ||
           (mode == AdaptiveMode::kLinearY && axis != Axis::kY)))
        entry.fail("motion_compensation",
                   std::string("compensates along motion_compensation.axis (") +
                       (axis == Axis::kX ? "x" : "y") + "), not along this mode's motion");
    }
    entry.done();
  }
  modes.done();
  a.enabled = true;
  m.done();
}

void parseRuntime(const YamlMap& m, RuntimeConfig& r) {
  r.queue_depth = m.get<int>("queue_depth", r.queue_depth);
  if (r.queue_depth < 1 || r.queue_depth > 64) m.fail("queue_depth", "must be in 1..64");
  r.default_pattern = m.get<std::string>("default_pattern", r.default_pattern);
  r.recording_root = m.get<std::string>("recording_root", r.recording_root);
  if (r.recording_root.empty()) m.fail("recording_root", "must not be empty");
  const std::string trigger = m.get<std::string>("trigger", "hardware");
  if (trigger == "hardware") r.trigger = TriggerMode::kHardware;
  else if (trigger == "software") r.trigger = TriggerMode::kSoftware;
  else m.fail("trigger", "must be hardware or software, not '" + trigger + "'");
  r.stall_timeout_s = m.get<double>("stall_timeout_s", r.stall_timeout_s);
  r.publish_implausible = m.get<bool>("publish_implausible", r.publish_implausible);
  if (!(r.stall_timeout_s >= 0.1 && r.stall_timeout_s <= 3600))
    m.fail("stall_timeout_s", "must be in [0.1, 3600] seconds");
  r.prefault_memory = m.get<bool>("prefault_memory", r.prefault_memory);
  r.last_error_hold_s = m.get<double>("last_error_hold_s", r.last_error_hold_s);
  if (!(r.last_error_hold_s >= 0 && r.last_error_hold_s <= 1e6))
    m.fail("last_error_hold_s", "must be in [0, 1e6] seconds (0 = until cleared)");
  auto count = [&](const char* key, std::uint64_t fallback, std::uint64_t max) {
    const double v = m.get<double>(key, static_cast<double>(fallback));
    if (!(v >= 0 && v <= static_cast<double>(max) && v == static_cast<double>(static_cast<std::uint64_t>(v))))
      m.fail(key, "must be a whole number in 0.." + std::to_string(max) + " (0 = no limit)");
    return static_cast<std::uint64_t>(v);
  };
  r.recording_max_mb = count("recording_max_mb", r.recording_max_mb, 1ull << 40);
  r.recording_max_sets = count("recording_max_sets", r.recording_max_sets, 1ull << 40);
  r.recording_min_free_mb = count("recording_min_free_mb", r.recording_min_free_mb, 1ull << 40);
  m.done();
}

void parseSoftwareTrigger(const YamlMap& m, SoftwareTriggerConfig& s) {
  s.settle_s = m.get<double>("settle_s", s.settle_s);
  if (!(s.settle_s >= 0 && s.settle_s <= 10)) m.fail("settle_s", "must be in [0, 10] seconds");
  s.grab_timeout_s = positive(m, "grab_timeout_s", s.grab_timeout_s);
  m.done();
}

// `replay:` {dir or file, loop, cache_mb}: a recording folder (dir) or an
// MCAP file of the daemon's image sets (file). Returns the recording's
// camera frame rate (from the first set's frame stamps), which the
// synchroniser's windows need.
double parseReplay(const YamlMap& m, const std::filesystem::path& base_dir,
                   drivers::ReplayConfig& replay, std::vector<std::string>& camera_ids) {
  const bool has_dir = m.has("dir"), has_file = m.has("file");
  if (has_dir == has_file)
    m.fail(has_dir ? "file" : "dir", "give the recording as dir (a folder) or file (an MCAP file), one of them");
  const std::string key = has_dir ? "dir" : "file";
  std::filesystem::path dir(m.get<std::string>(key));
  if (dir.is_relative()) dir = base_dir / dir;
  replay.dir = dir.lexically_normal().string();
  replay.loop = m.get<bool>("loop", replay.loop);
  replay.cache_bytes = static_cast<std::size_t>(
      nonNegative(m, "cache_mb", double(replay.cache_bytes >> 20)) * double(1 << 20));
  m.done();
  if (std::filesystem::exists(replay.dir) && std::filesystem::is_directory(replay.dir) != has_dir)
    m.fail(key, "'" + replay.dir + "' is " + (has_dir ? "not a folder (an MCAP file is given as file:)"
                                                      : "a folder (a recording folder is given as dir:)"));
  pipeline::ImageSet first;
  try {
    first = drivers::RecordingReader::open(replay.dir)->info(0);
  } catch (const std::exception& e) {
    m.fail(key, e.what());
  }
  for (const auto& camera : first.cameras) camera_ids.push_back(camera.camera_id);
  const auto& stamps = first.cameras.front().stamps_ns;
  if (stamps.size() < 2) return 30.0;
  const double interval_s = (stamps.back() - stamps.front()) * 1e-9 / double(stamps.size() - 1);
  if (!(interval_s > 0)) m.fail("dir", "the recording's frame stamps do not increase");
  return 1.0 / interval_s;
}

// The cameras the config declares, in the devices' order: the simulated
// ones, `cameras:` (hardware, fake_gige), or a recording's (replay).
std::vector<std::string> declaredCameraIds(const DaemonConfig& config,
                                           const std::vector<std::string>& replay_ids) {
  std::vector<std::string> ids;
  switch (config.sensor) {
    case SensorKind::kSim:
      ids.push_back(config.sim.camera_id);
      if (config.sim.second_camera) ids.push_back(config.sim.second_camera->camera_id);
      break;
    case SensorKind::kHardware:
    case SensorKind::kFakeGige:
      for (const auto& c : config.aravis.cameras) ids.push_back(c.name);
      break;
    case SensorKind::kReplay:
      ids = replay_ids;
      break;
  }
  return ids;
}

// Cross-references that need no device, checked at load so that a mistake
// is a config error (exit 2) before any device is opened: the cameras named
// by patterns[].cameras, patterns[].intensity_camera and calibrations: are
// cameras the config declares, each with a calibration (the first camera
// has calibration:); a region of interest matches its camera's calibration.
// The engine checks the pattern cameras again against the opened devices.
void checkCameraReferences(const YamlMap& root, const DaemonConfig& config,
                           const std::vector<std::string>& replay_ids) {
  const std::vector<std::string> ids = declaredCameraIds(config, replay_ids);
  if (ids.empty()) return;
  std::string list;
  for (const auto& id : ids) list += (list.empty() ? "" : ", ") + id;
  const auto declared = [&](const std::string& id) {
    return std::find(ids.begin(), ids.end(), id) != ids.end();
  };
  const auto check = [&](const std::string& pattern, const std::string& id, const char* role) {
    if (!declared(id))
      root.fail("patterns", "pattern '" + pattern + "' " + role + " camera '" + id +
                                "', which the sensor does not have (its cameras: " + list + ")");
    if (id != ids.front() && !config.extra_calibrations.count(id))
      root.fail("patterns", "pattern '" + pattern + "' " + role + " camera '" + id +
                                "', which has no calibration (calibration: is the first camera's, '" +
                                ids.front() + "'; give the others in calibrations:)");
  };
  for (const auto& [pattern, cameras] : config.pattern_cameras)
    for (const auto& id : cameras) check(pattern, id, "names");
  for (const auto& [pattern, id] : config.pattern_intensity_camera)
    check(pattern, id, "takes its intensity from");
  if (config.sensor != SensorKind::kSim)  // the simulated second camera's rig is added by the loader
    for (const auto& [id, calibration] : config.extra_calibrations)
      if (!declared(id))
        root.fail("calibrations", "camera '" + id + "' is not a camera of the sensor (its cameras: " +
                                      list + ")");
  for (std::size_t i = 0; i < config.aravis.cameras.size(); ++i) {
    const auto& c = config.aravis.cameras[i];
    const auto extra = config.extra_calibrations.find(c.name);
    const pipeline::PinholeModel* model =
        i == 0 ? &config.calibration.camera
               : extra != config.extra_calibrations.end() ? &extra->second.camera : nullptr;
    if (!model) continue;
    if ((c.width != 0 && c.width != model->width) || (c.height != 0 && c.height != model->height))
      root.fail("cameras", "camera '" + c.name + "': roi " + std::to_string(c.width) + "x" +
                               std::to_string(c.height) + " differs from its calibration's " +
                               std::to_string(model->width) + "x" + std::to_string(model->height) +
                               " images");
  }
}

DaemonConfig parseRoot(const YAML::Node& root_node, const std::string& origin,
                       const std::filesystem::path& base_dir) {
  DaemonConfig config;
  config.source_path = origin;
  const YamlMap root(root_node, origin, "");
  const std::string sensor = root.get<std::string>("sensor", toString(config.sensor));
  bool known = false;
  for (const SensorKind kind :
       {SensorKind::kSim, SensorKind::kHardware, SensorKind::kFakeGige, SensorKind::kReplay})
    if (sensor == toString(kind)) {
      config.sensor = kind;
      known = true;
    }
  if (!known)
    root.fail("sensor", "unknown sensor '" + sensor + "' (supported: sim, hardware, fake_gige, replay)");
  // fake_gige renders with the simulator; replay plays a recording.
  const bool simulated = config.sensor == SensorKind::kSim || config.sensor == SensorKind::kFakeGige;
  if (simulated) parseSim(root.map("sim"), base_dir, config.sim);
  const bool replay = config.sensor == SensorKind::kReplay;
  double replay_fps = 0;
  std::vector<std::string> replay_camera_ids;
  if (replay) replay_fps = parseReplay(root.map("replay"), base_dir, config.replay, replay_camera_ids);

  // `calibration:` sim, a file path, or {file, keys} for a foreign OpenCV
  // FileStorage file read through a key mapping (calibration_io.h).
  std::string calibration = "sim", calibration_keys;
  if (root.has("calibration") && root.raw("calibration").IsMap()) {
    const YamlMap c(root.raw("calibration"), root.origin(), root.keyPath("calibration"));
    calibration = c.get<std::string>("file");
    if (c.has("keys")) {
      const YAML::Node keys = c.raw("keys");
      if (keys.IsMap()) {
        // Inline mapping: written back as dotted pairs for the one parser.
        for (const auto& device : keys) {
          const std::string name = device.first.as<std::string>();
          if (device.second.IsMap()) {
            for (const auto& entry : device.second)
              calibration_keys += (calibration_keys.empty() ? "" : ",") + name + "." +
                                  entry.first.as<std::string>() + "=" +
                                  entry.second.as<std::string>();
          } else {
            calibration_keys += (calibration_keys.empty() ? "" : ",") + name + "=" +
                                device.second.as<std::string>();
          }
        }
      } else {
        std::filesystem::path keys_path(keys.as<std::string>());
        if (keys_path.is_relative()) keys_path = base_dir / keys_path;
        if (!std::filesystem::exists(keys_path))
          c.fail("keys", "cannot read key-mapping file '" + keys_path.string() + "'");
        calibration_keys = keys_path.string();
      }
    } else {
      c.fail("keys", "is required with `file` (the key mapping of the OpenCV file; a plain "
                     "`calibration: PATH` reads the project's and SLStudio's formats)");
    }
    c.done();
  } else {
    calibration = root.get<std::string>("calibration", "sim");
  }
  if (calibration == "sim") {
    if (!simulated)
      root.fail("calibration", std::string("a ") + toString(config.sensor) +
                                   " sensor needs a calibration file");
    config.calibration = config.sim.rig;
    // The simulated second camera triangulates with its true rig too.
    if (config.sim.second_camera)
      config.extra_calibrations[config.sim.second_camera->camera_id] = config.sim.second_camera->rig;
  } else {
    std::filesystem::path path(calibration);
    if (path.is_relative()) path = base_dir / path;
    if (!std::filesystem::is_regular_file(path))
      root.fail("calibration", "cannot read calibration file '" + path.string() + "': " +
                                   (std::filesystem::is_directory(path) ? "a directory"
                                    : std::filesystem::exists(path)      ? "not a regular file"
                                                                         : "no such file"));
    config.calibration =
        calibration_keys.empty()
            ? loadCalibration(path.string()).calibration
            : loadOpenCvCalibration(path.string(), parseOpenCvCalibrationKeys(calibration_keys))
                  .calibration;
  }
  if (simulated &&
      (config.calibration.camera.width != config.sim.rig.camera.width ||
       config.calibration.camera.height != config.sim.rig.camera.height))
    root.fail("calibration", "camera size differs from the sensor's camera");

  parsePatterns(root, config.calibration.projector, base_dir, config);
  parseExtraCalibrations(root, base_dir, config);
  config.sim.patterns = config.patterns;
  const bool hardware = config.sensor == SensorKind::kHardware;
  if (hardware) parseHardware(root, config);
  if (hardware || config.sensor == SensorKind::kFakeGige) parseAravisSection(root, config);
  parseDecoder(root.optionalMap("decoder"), config.decoder);
  parseTriangulator(root.optionalMap("triangulator"), config.triangulator);
  parseSynchroniser(root.optionalMap("synchroniser"),
                    hardware ? hardwareImageRate(root, config)
                    : replay                    ? replay_fps
                                                : config.sim.camera_fps,
                    config.synchroniser);
  parseMotion(root.optionalMap("motion_compensation"), config.motion);
  parseDds(root.optionalMap("dds"), config.dds, base_dir);
  parseRuntime(root.optionalMap("runtime"), config.runtime);
  parseSoftwareTrigger(root.optionalMap("software_trigger"), config.software_trigger);
  parseCameraNoise(root, config);
  if (root.has("adaptive")) parseAdaptive(root.map("adaptive"), config, config.adaptive);
  // Relative: under the service's state directory when systemd gives one
  // (StateDirectory=, $STATE_DIRECTORY), else under the user's data folder
  // ($XDG_DATA_HOME/sl-sensor, ~/.local/share/sl-sensor): never in the source
  // tree; beside the config file only without any of these.
  if (std::filesystem::path(config.runtime.recording_root).is_relative()) {
    const auto env = [](const char* name) {
      const char* v = std::getenv(name);
      return std::string(v ? v : "");
    };
    const std::string state = env("STATE_DIRECTORY");
    const std::filesystem::path base =
        !state.empty()                   ? std::filesystem::path(state.substr(0, state.find(':')))
        : !env("XDG_DATA_HOME").empty() ? std::filesystem::path(env("XDG_DATA_HOME")) / "sl-sensor"
        : !env("HOME").empty()           ? std::filesystem::path(env("HOME")) / ".local/share/sl-sensor"
                                         : base_dir;
    config.runtime.recording_root =
        std::filesystem::absolute(base / config.runtime.recording_root).lexically_normal().string();
  }
  if (config.runtime.default_pattern.empty()) {
    config.runtime.default_pattern = config.patterns.front().name;
  } else if (!config.findPattern(config.runtime.default_pattern)) {
    throw ConfigError(origin + ": key 'runtime.default_pattern': no pattern named '" +
                      config.runtime.default_pattern + "'");
  }
  checkCameraReferences(root, config, replay_camera_ids);
  root.done();
  return config;
}

}  // namespace

const char* toString(SensorKind kind) {
  switch (kind) {
    case SensorKind::kSim: return "sim";
    case SensorKind::kHardware: return "hardware";
    case SensorKind::kFakeGige: return "fake_gige";
    case SensorKind::kReplay: return "replay";
  }
  return "?";
}

const pipeline::PatternSpec* DaemonConfig::findPattern(const std::string& name) const {
  for (const auto& p : patterns)
    if (p.name == name) return &p;
  return nullptr;
}

namespace {

DaemonConfig parseText(const std::string& text, const std::string& origin,
                       const std::filesystem::path& base_dir) {
  YAML::Node root;
  try {
    root = parseInputYaml(text, origin);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " +
                      e.msg);
  }
  if (!root.IsMap()) throw ConfigError(origin + ": expected a map of keys at the top level");
  DaemonConfig config;
  try {
    config = parseRoot(root, origin, base_dir);
  } catch (const YAML::Exception& e) {
    // A conversion the readers did not foresee (e.g. a key that is a list):
    // still one line naming the file and line (found by fuzz_config).
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": unexpected YAML: " + e.msg);
  }
  config.source_text = text;
  return config;
}

}  // namespace

DaemonConfig parseConfig(const std::string& yaml_text, const std::string& origin) {
  return parseText(yaml_text, origin, std::filesystem::current_path());
}

DaemonConfig loadConfig(const std::string& path) {
  return parseText(readInputFile(path, InputKind::kConfig), path,
                   std::filesystem::path(path).parent_path());
}

}  // namespace sl::daemon
