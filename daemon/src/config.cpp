#include "sl/daemon/config.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <set>
#include <sstream>

#include <Eigen/Geometry>

#include "yaml_reader.h"

namespace sl::daemon {

namespace {

Eigen::Vector3d vec3(const YamlMap& m, const std::string& key) {
  const auto v = m.get<std::vector<double>>(key);
  if (v.size() != 3) m.fail(key, "expected 3 numbers, found " + std::to_string(v.size()));
  return {v[0], v[1], v[2]};
}

Eigen::Vector3d vec3(const YamlMap& m, const std::string& key, const Eigen::Vector3d& fallback) {
  return m.has(key) ? vec3(m, key) : fallback;
}

double positive(const YamlMap& m, const std::string& key, double fallback) {
  const double v = m.get<double>(key, fallback);
  if (!(v > 0)) m.fail(key, "must be > 0");
  return v;
}

double nonNegative(const YamlMap& m, const std::string& key, double fallback) {
  const double v = m.get<double>(key, fallback);
  if (!(v >= 0)) m.fail(key, "must be >= 0");
  return v;
}

pipeline::PinholeModel parsePinhole(const YamlMap& m) {
  pipeline::PinholeModel model;
  model.width = m.get<int>("width");
  model.height = m.get<int>("height");
  if (model.width <= 0) m.fail("width", "must be > 0");
  if (model.height <= 0) m.fail("height", "must be > 0");
  model.fx = positive(m, "fx", 0);
  model.fy = positive(m, "fy", 0);
  model.cx = m.get<double>("cx");
  model.cy = m.get<double>("cy");
  const auto d = m.get<std::vector<double>>("distortion", {0, 0, 0, 0, 0});
  if (d.size() != 5) m.fail("distortion", "expected 5 numbers (k1 k2 p1 p2 k3)");
  std::copy(d.begin(), d.end(), model.distortion.begin());
  m.done();
  return model;
}

// Projector pose relative to the camera: X_p = R * X_c + t.
void parsePose(const YamlMap& m, pipeline::CameraProjectorCalibration& c) {
  const bool has_matrix = m.has("rotation");
  const bool has_angles = m.has("rotation_deg");
  if (has_matrix == has_angles)
    m.fail(has_matrix ? "rotation" : "rotation_deg",
           "give exactly one of 'rotation' (9 numbers, row-major) or 'rotation_deg' "
           "([rx, ry, rz], R = Rz * Ry * Rx)");
  if (has_matrix) {
    const auto r = m.get<std::vector<double>>("rotation");
    if (r.size() != 9) m.fail("rotation", "expected 9 numbers (row-major 3x3)");
    c.R = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(r.data());
    if ((c.R * c.R.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
        c.R.determinant() < 0)
      m.fail("rotation", "is not a rotation matrix");
  } else {
    const Eigen::Vector3d a = vec3(m, "rotation_deg") * std::numbers::pi / 180.0;
    c.R = (Eigen::AngleAxisd(a.z(), Eigen::Vector3d::UnitZ()) *
           Eigen::AngleAxisd(a.y(), Eigen::Vector3d::UnitY()) *
           Eigen::AngleAxisd(a.x(), Eigen::Vector3d::UnitX()))
              .toRotationMatrix();
  }
  c.t = vec3(m, "translation_mm");
  m.done();
}

pipeline::CameraProjectorCalibration parseCalibration(const YamlMap& m) {
  pipeline::CameraProjectorCalibration c;
  c.camera = parsePinhole(m.map("camera"));
  c.projector = parsePinhole(m.map("projector"));
  parsePose(m.map("projector_pose"), c);
  m.done();
  return c;
}

drivers::SimScene parseScene(const YamlMap& sim) {
  drivers::SimScene scene;
  for (const YamlMap& item : sim.listOfMaps("scene")) {
    const bool plane = item.has("plane"), sphere = item.has("sphere");
    if (plane == sphere) item.fail(plane ? "plane" : "sphere",
                                   "each scene item is exactly one of 'plane' or 'sphere'");
    if (plane) {
      const YamlMap p = item.map("plane");
      drivers::SimPlane s;
      s.point = vec3(p, "point_mm");
      s.normal = vec3(p, "normal", s.normal);
      if (s.normal.norm() == 0) p.fail("normal", "must not be zero");
      s.albedo = p.get<double>("albedo", s.albedo);
      if (s.albedo < 0 || s.albedo > 1) p.fail("albedo", "must be in [0, 1]");
      p.done();
      scene.planes.push_back(s);
    } else {
      const YamlMap p = item.map("sphere");
      drivers::SimSphere s;
      s.center = vec3(p, "center_mm");
      s.radius = positive(p, "radius_mm", 0);
      s.albedo = p.get<double>("albedo", s.albedo);
      if (s.albedo < 0 || s.albedo > 1) p.fail("albedo", "must be in [0, 1]");
      p.done();
      scene.spheres.push_back(s);
    }
    item.done();
  }
  return scene;
}

void parseSim(const YamlMap& m, drivers::SimConfig& sim) {
  sim.seed = m.get<std::uint64_t>("seed", sim.seed);
  sim.camera_fps = positive(m, "camera_fps", sim.camera_fps);
  sim.bit_depth = m.get<int>("bit_depth", sim.bit_depth);
  if (sim.bit_depth < 8 || sim.bit_depth > 16) m.fail("bit_depth", "must be in 8..16");
  const YamlMap radiometry = m.optionalMap("radiometry");
  sim.projector_brightness_dn =
      nonNegative(radiometry, "projector_brightness_dn", sim.projector_brightness_dn);
  sim.reference_distance_mm =
      positive(radiometry, "reference_distance_mm", sim.reference_distance_mm);
  sim.ambient_dn = nonNegative(radiometry, "ambient_dn", sim.ambient_dn);
  sim.gain_dn_per_electron =
      nonNegative(radiometry, "gain_dn_per_electron", sim.gain_dn_per_electron);
  sim.read_noise_dn = nonNegative(radiometry, "read_noise_dn", sim.read_noise_dn);
  radiometry.done();
  const YamlMap rig = m.map("rig");
  sim.camera_id = rig.get<std::string>("camera_id", sim.camera_id);
  sim.rig = parseCalibration(YamlMap(rig.raw("calibration"), rig.origin(),
                                     rig.keyPath("calibration")));
  rig.done();
  sim.scene = parseScene(m);
  m.done();
}

void parsePatterns(const YamlMap& root, const pipeline::PinholeModel& projector,
                   std::vector<pipeline::PhaseShift33Pattern>& patterns) {
  std::set<std::string> names;
  for (const YamlMap& m : root.listOfMaps("patterns")) {
    pipeline::PhaseShift33Pattern p;
    p.name = m.get<std::string>("name");
    if (p.name.empty()) m.fail("name", "must not be empty");
    if (!names.insert(p.name).second) m.fail("name", "duplicate pattern name '" + p.name + "'");
    const std::string family = m.get<std::string>("family", "phase_shift_3+3");
    if (family != "phase_shift_3+3")
      m.fail("family", "unknown pattern family '" + family + "' (supported: phase_shift_3+3)");
    try {
      p.direction = pipeline::directionFromString(m.get<std::string>("direction"));
    } catch (const std::invalid_argument& e) {
      m.fail("direction", e.what());
    }
    p.fringes = m.get<int>("fringes", p.fringes);
    p.projector_width = projector.width;
    p.projector_height = projector.height;
    try {
      p.validate();
    } catch (const std::invalid_argument& e) {
      m.fail("fringes", e.what());
    }
    m.done();
    patterns.push_back(p);
  }
}

void parseDecoder(const YamlMap& m, pipeline::DecoderOptions& d) {
  d.min_modulation = static_cast<float>(nonNegative(m, "min_modulation", d.min_modulation));
  d.reject_saturated = m.get<bool>("reject_saturated", d.reject_saturated);
  d.max_unwrap_error = static_cast<float>(positive(m, "max_unwrap_error", d.max_unwrap_error));
  if (d.max_unwrap_error >= 0.5f) m.fail("max_unwrap_error", "must be < 0.5 (periods)");
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

void parseDds(const YamlMap& m, DdsConfig& d) {
  d.domain_id = m.get<int>("domain_id", d.domain_id);
  if (d.domain_id < 0 || d.domain_id > 232) m.fail("domain_id", "must be in 0..232");
  d.ns = m.get<std::string>("namespace", d.ns);
  if (d.ns.empty() || d.ns.find_first_not_of(
                          "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_/") !=
                          std::string::npos || d.ns.front() == '/' || d.ns.back() == '/')
    m.fail("namespace", "must be non-empty letters, digits, '_' or inner '/'");
  d.frame_id = m.get<std::string>("frame_id", d.frame_id);
  d.publish_projector_maps = m.get<bool>("publish_projector_maps", d.publish_projector_maps);
  d.publish_image_sets = m.get<bool>("publish_image_sets", d.publish_image_sets);
  d.status_period_s = positive(m, "status_period_s", d.status_period_s);
  m.done();
}

void parseRuntime(const YamlMap& m, RuntimeConfig& r) {
  r.queue_depth = m.get<int>("queue_depth", r.queue_depth);
  if (r.queue_depth < 1 || r.queue_depth > 64) m.fail("queue_depth", "must be in 1..64");
  r.default_pattern = m.get<std::string>("default_pattern", r.default_pattern);
  m.done();
}

DaemonConfig parseRoot(const YAML::Node& root_node, const std::string& origin,
                       const std::filesystem::path& base_dir) {
  DaemonConfig config;
  config.source_path = origin;
  const YamlMap root(root_node, origin, "");
  config.sensor = root.get<std::string>("sensor", config.sensor);
  if (config.sensor != "sim")
    root.fail("sensor", "unknown sensor '" + config.sensor +
                            "' (this build supports: sim; hardware drivers are not built yet)");
  parseSim(root.map("sim"), config.sim);

  const std::string calibration = root.get<std::string>("calibration", "sim");
  if (calibration == "sim") {
    config.calibration = config.sim.rig;
  } else {
    std::filesystem::path path(calibration);
    if (path.is_relative()) path = base_dir / path;
    YAML::Node node;
    try {
      node = YAML::LoadFile(path.string());
    } catch (const YAML::BadFile&) {
      root.fail("calibration", "cannot read calibration file '" + path.string() + "'");
    } catch (const YAML::Exception& e) {
      throw ConfigError(path.string() + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
    }
    config.calibration = parseCalibration(YamlMap(node, path.string(), ""));
  }
  if (config.calibration.camera.width != config.sim.rig.camera.width ||
      config.calibration.camera.height != config.sim.rig.camera.height)
    root.fail("calibration", "camera size differs from the sensor's camera");

  parsePatterns(root, config.calibration.projector, config.patterns);
  config.sim.patterns = config.patterns;
  parseDecoder(root.optionalMap("decoder"), config.decoder);
  parseTriangulator(root.optionalMap("triangulator"), config.triangulator);
  parseSynchroniser(root.optionalMap("synchroniser"), config.sim.camera_fps, config.synchroniser);
  parseDds(root.optionalMap("dds"), config.dds);
  parseRuntime(root.optionalMap("runtime"), config.runtime);
  if (config.runtime.default_pattern.empty()) {
    config.runtime.default_pattern = config.patterns.front().name;
  } else if (!config.findPattern(config.runtime.default_pattern)) {
    throw ConfigError(origin + ": key 'runtime.default_pattern': no pattern named '" +
                      config.runtime.default_pattern + "'");
  }
  root.done();
  return config;
}

}  // namespace

const pipeline::PhaseShift33Pattern* DaemonConfig::findPattern(const std::string& name) const {
  for (const auto& p : patterns)
    if (p.name == name) return &p;
  return nullptr;
}

namespace {

DaemonConfig parseText(const std::string& text, const std::string& origin,
                       const std::filesystem::path& base_dir) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " +
                      e.msg);
  }
  if (!root.IsMap()) throw ConfigError(origin + ": expected a map of keys at the top level");
  return parseRoot(root, origin, base_dir);
}

}  // namespace

DaemonConfig parseConfig(const std::string& yaml_text, const std::string& origin) {
  return parseText(yaml_text, origin, std::filesystem::current_path());
}

DaemonConfig loadConfig(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open config file");
  std::stringstream text;
  text << in.rdbuf();
  return parseText(text.str(), path, std::filesystem::path(path).parent_path());
}

}  // namespace sl::daemon
