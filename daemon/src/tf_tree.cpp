#include "tf_tree.h"

#include <cmath>
#include <map>
#include <utility>

#include "sl/files/config_error.h"
#include "sl/files/input_file.h"
#include "sl/files/yaml_reader.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::ConfigError;
using ::sl::files::InputKind;
using ::sl::files::YamlMap;
using ::sl::files::loadInputYaml;

namespace {

void checkFrame(const YamlMap& m, const char* key, const std::string& frame, bool may_be_empty) {
  if (frame.empty() && may_be_empty) return;
  if (frame.empty() || frame.size() > 128 || frame.front() == '/' ||
      frame.find_first_of(" \t\n\"'") != std::string::npos)
    m.fail(key, "must be 1..128 characters without spaces, quotes or a leading '/' (tf2 frame ids)");
}

// The mount from an sl_handeye result (format sl-sensor-hand-eye/1): its
// `mount` is the first camera's optical frame in the flange (eye-in-hand) or
// in the robot base (eye-to-hand), translation in mm. base_frame shares the
// optical frame's origin with body axes: p_parent = R_mount opticalToBody()^T
// p_base + t.
void readHandEyeMount(const YamlMap& mount, const std::string& path, TfConfig& tf) {
  YAML::Node root;
  try {
    root = loadInputYaml(path, InputKind::kCalibration);
  } catch (const ConfigError& e) {
    mount.fail("hand_eye", e.what());
  }
  const auto fail = [&](const std::string& what) {
    mount.fail("hand_eye", "'" + path + "': " + what + " (write it with sl_handeye --out)");
  };
  if (!root.IsMap() || !root["format"] || root["format"].as<std::string>("") != "sl-sensor-hand-eye/1")
    fail("not an sl_handeye result (format: sl-sensor-hand-eye/1)");
  const YAML::Node m = root["mount"];
  if (!m || !m.IsMap() || !m["translation_mm"] || !m["quaternion_xyzw"]) fail("no mount: {translation_mm, quaternion_xyzw}");
  std::vector<double> t, q;
  try {
    t = m["translation_mm"].as<std::vector<double>>();
    q = m["quaternion_xyzw"].as<std::vector<double>>();
  } catch (const YAML::Exception&) {
    fail("mount.translation_mm and mount.quaternion_xyzw must be lists of numbers");
  }
  if (t.size() != 3 || q.size() != 4) fail("mount.translation_mm needs 3 numbers, mount.quaternion_xyzw 4");
  for (double v : t)
    if (!std::isfinite(v) || std::abs(v) > 1e7) fail("mount.translation_mm is not finite millimetres below 10 km");
  const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(std::abs(norm - 1.0) <= 1e-3)) fail("mount.quaternion_xyzw is not a unit quaternion");
  const Eigen::Quaterniond optical(q[3] / norm, q[0] / norm, q[1] / norm, q[2] / norm);
  const Eigen::Quaterniond base(optical.toRotationMatrix() * opticalToBody().transpose());
  tf.mount_xyz_m = {t[0] * 1e-3, t[1] * 1e-3, t[2] * 1e-3};
  tf.mount_xyzw = {base.x(), base.y(), base.z(), base.w()};
}

}  // namespace

void parseTfConfig(const YamlMap& m, TfConfig& tf, const std::filesystem::path& base_dir) {
  tf.publish = m.get<bool>("publish", tf.publish);
  tf.parent_frame = m.get<std::string>("parent_frame", tf.parent_frame);
  tf.base_frame = m.get<std::string>("base_frame", tf.base_frame);
  tf.projector_frame = m.get<std::string>("projector_frame", tf.projector_frame);
  checkFrame(m, "parent_frame", tf.parent_frame, true);
  checkFrame(m, "base_frame", tf.base_frame, false);
  checkFrame(m, "projector_frame", tf.projector_frame, false);
  if (tf.parent_frame == tf.base_frame) m.fail("parent_frame", "must differ from base_frame");
  const YamlMap mount = m.optionalMap("mount");
  if (mount.has("xyz") || mount.has("rpy") || mount.has("quaternion")) {
    if (tf.parent_frame.empty())
      mount.fail("xyz", "a mount pose needs dds.tf.parent_frame (the frame it is given in)");
  }
  if (mount.has("hand_eye")) {
    if (mount.has("xyz") || mount.has("rpy") || mount.has("quaternion"))
      mount.fail("hand_eye", "give the mount as hand_eye (a file) or as xyz + rpy|quaternion, not both");
    if (tf.parent_frame.empty())
      mount.fail("hand_eye", "a mount pose needs dds.tf.parent_frame (the flange or base frame of the hand-eye calibration)");
    std::filesystem::path path(mount.get<std::string>("hand_eye"));
    if (path.is_relative()) path = base_dir / path;
    readHandEyeMount(mount, path.lexically_normal().string(), tf);
  }
  if (mount.has("xyz")) {
    const std::vector<double> xyz = mount.get<std::vector<double>>("xyz");
    if (xyz.size() != 3) mount.fail("xyz", "expected [x, y, z] in metres");
    for (double v : xyz)
      if (!std::isfinite(v) || std::abs(v) > 1e4) mount.fail("xyz", "expected finite metres below 10 km");
    tf.mount_xyz_m = {xyz[0], xyz[1], xyz[2]};
  }
  if (mount.has("rpy") && mount.has("quaternion"))
    mount.fail("quaternion", "give the rotation as rpy or as quaternion, not both");
  if (mount.has("rpy")) {
    const std::vector<double> rpy = mount.get<std::vector<double>>("rpy");
    if (rpy.size() != 3) mount.fail("rpy", "expected [roll, pitch, yaw] in radians");
    for (double v : rpy)
      if (!std::isfinite(v) || std::abs(v) > 100) mount.fail("rpy", "expected finite radians");
    const Eigen::Quaterniond q = Eigen::AngleAxisd(rpy[2], Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(rpy[1], Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(rpy[0], Eigen::Vector3d::UnitX());
    tf.mount_xyzw = {q.x(), q.y(), q.z(), q.w()};
  }
  if (mount.has("quaternion")) {
    const std::vector<double> q = mount.get<std::vector<double>>("quaternion");
    if (q.size() != 4) mount.fail("quaternion", "expected [x, y, z, w]");
    const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(std::abs(norm - 1.0) <= 1e-3))
      mount.fail("quaternion", "must be a unit quaternion [x, y, z, w] (its norm is " +
                                   std::to_string(norm) + ")");
    tf.mount_xyzw = {q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm};
  }
  mount.done();
  m.done();
}

Eigen::Matrix3d opticalToBody() {
  Eigen::Matrix3d r;
  // Columns: the optical axes x (right), y (down), z (forward) in body axes.
  r << 0, 0, 1,
      -1, 0, 0,
       0, -1, 0;
  return r;
}

std::vector<FrameTransform> sensorTransforms(const TfConfig& tf, const std::vector<CameraFrame>& cameras) {
  std::vector<FrameTransform> out;
  if (cameras.empty()) return out;
  std::vector<std::pair<std::string, std::string>> frames{{"dds.tf.base_frame", tf.base_frame},
                                                          {"dds.tf.projector_frame", tf.projector_frame}};
  if (!tf.parent_frame.empty()) frames.emplace_back("dds.tf.parent_frame", tf.parent_frame);
  frames.emplace_back("dds.frame_id", cameras.front().frame_id);
  for (std::size_t i = 1; i < cameras.size(); ++i)
    frames.emplace_back("the optical frame of camera '" + cameras[i].id + "'", cameras[i].frame_id);
  std::map<std::string, std::string> seen;  // frame -> what named it first
  for (const auto& [what, frame] : frames)
    if (const auto [it, fresh] = seen.emplace(frame, what); !fresh)
      throw ConfigError("dds.tf: " + what + " and " + it->second + " are both '" + frame +
                        "' (the sensor's tf frames must all differ)");
  if (!tf.parent_frame.empty()) {
    FrameTransform mount{tf.parent_frame, tf.base_frame, Eigen::Isometry3d::Identity()};
    mount.pose.linear() =
        Eigen::Quaterniond(tf.mount_xyzw[3], tf.mount_xyzw[0], tf.mount_xyzw[1], tf.mount_xyzw[2])
            .normalized()
            .toRotationMatrix();
    mount.pose.translation() = Eigen::Vector3d(tf.mount_xyz_m[0], tf.mount_xyz_m[1], tf.mount_xyz_m[2]);
    out.push_back(mount);
  }
  const pipeline::CameraProjectorCalibration& first = cameras.front().calibration;
  for (const auto& c : cameras) {
    // X_first = to_first * X_c (mm), then into the body axes.
    Eigen::Isometry3d to_first = pipeline::cameraToCamera(c.calibration, first);
    to_first.translation() *= 1e-3;
    FrameTransform t{tf.base_frame, c.frame_id, Eigen::Isometry3d::Identity()};
    t.pose.linear() = opticalToBody();
    t.pose = t.pose * to_first;
    out.push_back(t);
  }
  // X_p = R X_c + t  =>  X_c = R^T X_p - R^T t.
  FrameTransform projector{cameras.front().frame_id, tf.projector_frame, Eigen::Isometry3d::Identity()};
  projector.pose.linear() = first.R.transpose();
  projector.pose.translation() = -(first.R.transpose() * first.t) * 1e-3;
  out.push_back(projector);
  return out;
}

}  // namespace sl::daemon
