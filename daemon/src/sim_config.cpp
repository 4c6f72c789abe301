// The simulated sensor's section (`sim:`): scene, optics, noise, motion,
// second camera.
#include <cmath>
#include <filesystem>
#include <numbers>

#include <Eigen/Geometry>

#include "sl/files/calibration_yaml.h"
#include "sim_config_yaml.h"
#include "sl/files/input_file.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::InputKind;
using ::sl::files::YamlMap;
using ::sl::files::checkInputFile;

namespace {

double albedo(const YamlMap& m, double fallback) {
  const double a = m.get<double>("albedo", fallback);
  if (a < 0 || a > 1) m.fail("albedo", "must be in [0, 1]");
  return a;
}

// R = Rz * Ry * Rx from rotation_deg [rx, ry, rz] (as projector_pose).
Eigen::Matrix3d rotationDeg(const YamlMap& m, const std::string& key) {
  const Eigen::Vector3d a = vec3(m, key, Eigen::Vector3d::Zero()) * std::numbers::pi / 180.0;
  return (Eigen::AngleAxisd(a.z(), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(a.y(), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(a.x(), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Isometry3d poseOf(const YamlMap& m) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rotationDeg(m, "rotation_deg");
  pose.translation() = vec3(m, "translation_mm", Eigen::Vector3d::Zero());
  return pose;
}

// An albedo image from the file named by `key` (relative to base_dir).
cv::Mat loadTexture(const YamlMap& m, const std::string& key,
                    const std::filesystem::path& base_dir) {
  std::filesystem::path file = m.get<std::string>(key);
  if (file.is_relative()) file = base_dir / file;
  try {
    // A regular file within the texture limit: OpenCV then reads it by path
    // (a FIFO would block it, a device feed it without end).
    if (std::filesystem::exists(file)) checkInputFile(file.string(), InputKind::kTexture);
    return drivers::loadAlbedoTexture(file.string());
  } catch (const std::runtime_error& e) {
    m.fail(key, e.what());
  }
}

// The items of a scene list (sim.scene or a group's items) into `scene`.
// Files (mesh PLY) are relative to base_dir.
void parseSceneItems(const std::vector<YamlMap>& items, const std::filesystem::path& base_dir,
                     drivers::SimScene& scene) {
  static const std::vector<std::string> kKinds = {"plane", "sphere", "cone", "box",
                                                  "height_field", "mesh", "group"};
  for (const YamlMap& item : items) {
    std::string kind;
    for (const std::string& k : kKinds)
      if (item.has(k)) kind = kind.empty() ? k : "";
    if (kind.empty())
      item.fail("plane", "each scene item is exactly one of 'plane' or 'sphere' "
                         "(or 'cone', 'box', 'height_field', 'mesh', 'group')");
    const YamlMap p = item.map(kind);
    if (kind == "plane") {
      drivers::SimPlane s;
      s.point = vec3(p, "point_mm");
      s.normal = vec3(p, "normal", s.normal);
      if (s.normal.norm() == 0) p.fail("normal", "must not be zero");
      s.albedo = albedo(p, s.albedo);
      if (p.has("texture")) {
        const YamlMap t = p.map("texture");
        drivers::SimPlaneTexture texture;
        texture.albedo = loadTexture(t, "file", base_dir);
        texture.center = vec3(t, "center_mm", s.point);
        texture.x_axis = vec3(t, "x_axis", texture.x_axis);
        const Eigen::Vector3d n = s.normal.normalized();
        if ((texture.x_axis - n * n.dot(texture.x_axis)).norm() < 1e-6 * texture.x_axis.norm())
          t.fail("x_axis", "must not be (nearly) parallel to the plane normal");
        texture.width_mm = t.get<double>("width_mm");
        if (!(texture.width_mm > 0)) t.fail("width_mm", "must be > 0");
        t.done();
        s.texture = texture;
      }
      scene.planes.push_back(s);
    } else if (kind == "sphere") {
      drivers::SimSphere s;
      s.center = vec3(p, "center_mm");
      s.radius = positive(p, "radius_mm", 0);
      s.albedo = albedo(p, s.albedo);
      scene.spheres.push_back(s);
    } else if (kind == "cone") {
      drivers::SimCone s;
      s.base_center = vec3(p, "base_center_mm");
      s.axis = vec3(p, "axis", s.axis);
      if (s.axis.norm() == 0) p.fail("axis", "must not be zero");
      s.radius = positive(p, "radius_mm", 0);
      s.height = positive(p, "height_mm", 0);
      s.albedo = albedo(p, s.albedo);
      scene.cones.push_back(s);
    } else if (kind == "box") {
      drivers::SimBox s;
      s.center = vec3(p, "center_mm");
      s.size_mm = vec3(p, "size_mm");
      if ((s.size_mm.array() <= 0).any()) p.fail("size_mm", "must be > 0");
      s.rotation = rotationDeg(p, "rotation_deg");
      s.albedo = albedo(p, s.albedo);
      scene.boxes.push_back(s);
    } else if (kind == "height_field") {
      drivers::SimHeightField s;
      s.origin = vec3(p, "origin_mm");
      s.normal = vec3(p, "normal", s.normal);
      s.x_axis = vec3(p, "x_axis", s.x_axis);
      s.width_mm = positive(p, "width_mm", s.width_mm);
      s.length_mm = positive(p, "length_mm", s.length_mm);
      s.cell_mm = positive(p, "cell_mm", s.cell_mm);
      s.albedo = albedo(p, s.albedo);
      if (p.has("roughness") == p.has("height_map"))
        p.fail("roughness", "give exactly one of 'roughness' and 'height_map'");
      if (p.has("height_map")) {
        // An image (grey, 8/16 bit) resampled to the field's grid, black = min_mm.
        const YamlMap h = p.map("height_map");
        const double min_mm = h.get<double>("min_mm", 0.0), max_mm = h.get<double>("max_mm");
        if (!(max_mm > min_mm)) h.fail("max_mm", "must exceed min_mm");
        const cv::Mat unit = loadTexture(h, "file", base_dir);
        s.heights_mm = drivers::heightsFromImage(unit, min_mm, max_mm,
                                                 int(std::lround(s.length_mm / s.cell_mm)) + 1,
                                                 int(std::lround(s.width_mm / s.cell_mm)) + 1);
        h.done();
      } else {
        const YamlMap r = p.map("roughness");
        drivers::SimRoughness rough;
        rough.rms_mm = nonNegative(r, "rms_mm", rough.rms_mm);
        rough.correlation_length_mm =
            positive(r, "correlation_length_mm", rough.correlation_length_mm);
        rough.hurst = positive(r, "hurst", rough.hurst);
        rough.seed = r.get<std::uint64_t>("seed", rough.seed);
        r.done();
        s.roughness = rough;
      }
      if (p.has("albedo_texture")) s.albedo_texture = loadTexture(p, "albedo_texture", base_dir);
      scene.height_fields.push_back(s);
    } else if (kind == "mesh") {
      std::filesystem::path file = p.get<std::string>("file");
      if (file.is_relative()) file = base_dir / file;
      const double scale = positive(p, "scale", 1.0);
      drivers::SimMesh mesh;
      try {
        if (std::filesystem::exists(file)) checkInputFile(file.string(), InputKind::kMesh);
        mesh = drivers::loadPlyMesh(file.string(), scale);
      } catch (const std::runtime_error& e) {
        p.fail("file", e.what());
      }
      mesh.pose = poseOf(p);
      mesh.albedo = albedo(p, mesh.albedo);
      scene.meshes.push_back(std::move(mesh));
    } else {
      // A composite: its items in its own frame, placed by one pose.
      drivers::SimScene group;
      parseSceneItems(p.listOfMaps("items"), base_dir, group);
      drivers::appendTransformed(scene, group, poseOf(p));
    }
    p.done();
    item.done();
  }
}

drivers::SimScene parseScene(const YamlMap& sim, const std::filesystem::path& base_dir) {
  drivers::SimScene scene;
  parseSceneItems(sim.listOfMaps("scene"), base_dir, scene);
  return scene;
}

// sim.motion (velocity_mm_s, or poses: [{rotation_deg, translation_mm}, ...])
// and sim.second_camera ({camera_id, calibration}).
void parseSimMotionAndCameras(const YamlMap& m, drivers::SimConfig& sim) {
  const YamlMap motion = m.optionalMap("motion");
  sim.motion.velocity_mm_s = vec3(motion, "velocity_mm_s", sim.motion.velocity_mm_s);
  if (motion.has("poses"))
    for (const YamlMap& pose : motion.listOfMaps("poses")) {
      Eigen::Isometry3d x = Eigen::Isometry3d::Identity();
      x.linear() = rotationDeg(pose, "rotation_deg");
      x.translation() = vec3(pose, "translation_mm", Eigen::Vector3d::Zero());
      pose.done();
      sim.motion.poses.push_back(x);
    }
  motion.done();
  if (m.has("second_camera")) {
    const YamlMap camera = m.map("second_camera");
    drivers::SimCamera second;
    second.camera_id = camera.get<std::string>("camera_id", second.camera_id);
    const YamlMap calibration(camera.raw("calibration"), camera.origin(),
                              camera.keyPath("calibration"));
    second.rig = parseCalibrationKeys(calibration);
    calibration.done();
    camera.done();
    sim.second_camera = second;
  }
}

}  // namespace

void parseSim(const YamlMap& m, const std::filesystem::path& base_dir, drivers::SimConfig& sim) {
  sim.seed = m.get<std::uint64_t>("seed", sim.seed);
  sim.camera_fps = positive(m, "camera_fps", sim.camera_fps);
  const std::uint64_t cache_mib = m.get<std::uint64_t>("signal_cache_mib", sim.signal_cache_mib);
  if (cache_mib > (std::uint64_t{1} << 20)) m.fail("signal_cache_mib", "must be <= 1048576 (1 TiB)");
  sim.signal_cache_mib = static_cast<std::size_t>(cache_mib);
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
  sim.exposure_ms = positive(radiometry, "exposure_ms", sim.exposure_ms);
  if (sim.exposure_ms > 1000.0 / sim.camera_fps)
    radiometry.fail("exposure_ms", "must fit in the frame interval (1000 / camera_fps ms)");
  sim.reference_exposure_ms =
      positive(radiometry, "reference_exposure_ms", sim.reference_exposure_ms);
  sim.analog_gain = positive(radiometry, "analog_gain", sim.analog_gain);
  sim.projector_gamma = positive(radiometry, "projector_gamma", sim.projector_gamma);
  sim.projector_response =
      radiometry.get<std::vector<double>>("projector_response", sim.projector_response);
  if (radiometry.has("projector_response")) {
    if (sim.projector_response.size() < 2)
      radiometry.fail("projector_response", "needs at least 2 samples");
    for (double v : sim.projector_response)
      if (!(v >= 0 && v <= 1)) radiometry.fail("projector_response", "values must be in [0, 1]");
    if (sim.projector_gamma != 1.0)
      radiometry.fail("projector_gamma", "must be 1 (or absent) when projector_response is given");
  }
  radiometry.done();
  const YamlMap rig = m.map("rig");
  sim.camera_id = rig.get<std::string>("camera_id", sim.camera_id);
  const YamlMap calibration(rig.raw("calibration"), rig.origin(), rig.keyPath("calibration"));
  sim.rig = parseCalibrationKeys(calibration);
  calibration.done();
  rig.done();
  // sim.optics.camera / .projector: thin-lens defocus (f_number 0 = pinhole).
  const YamlMap optics = m.optionalMap("optics");
  struct Device {
    std::string key;
    drivers::SimLens* lens;
    const pipeline::PinholeModel* model;
  };
  for (const Device& d : {Device{"camera", &sim.camera_lens, &sim.rig.camera},
                          Device{"projector", &sim.projector_lens, &sim.rig.projector}}) {
    const YamlMap l = optics.optionalMap(d.key);
    d.lens->focus_distance_mm = positive(l, "focus_distance_mm", d.lens->focus_distance_mm);
    d.lens->f_number = nonNegative(l, "f_number", d.lens->f_number);
    d.lens->pixel_pitch_um = positive(l, "pixel_pitch_um", d.lens->pixel_pitch_um);
    const double focal_mm = d.model->fx * d.lens->pixel_pitch_um * 1e-3;
    if (d.lens->f_number > 0 && d.lens->focus_distance_mm <= 2 * focal_mm)
      l.fail("focus_distance_mm", "must exceed twice the focal length fx * pixel_pitch (" +
                                      std::to_string(focal_mm) + " mm)");
    l.done();
  }
  optics.done();
  sim.scene = parseScene(m, base_dir);
  parseSimMotionAndCameras(m, sim);
  m.done();
}

}  // namespace sl::daemon
