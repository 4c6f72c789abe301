// The daemon in ROS 2's graph without DDS: the `dds.tf` keys and their
// errors, the sensor's transforms, and the levels /diagnostics gives the
// daemon's states. The wire (names, QoS, bytes) is checked by ctest
// ros2_graph (tests/ros2/ros2_graph.sh) with Foxglove's deserializer.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <unistd.h>

#include "ros_graph.h"
#include "sl/daemon/config.h"
#include "sl/files/config_error.h"
#include "support/config_text.h"
#include "tf_tree.h"

namespace {

using sl::files::ConfigError;
using sl::daemon::TfConfig;

// config/sim.yaml with `tf_block` (lines indented under dds:) added to dds.
std::string withTf(const std::string& tf_block) {
  std::string text = sl::test::shippedSimConfigText();
  const auto at = text.find("\ndds:\n");
  REQUIRE(at != std::string::npos);
  return text.insert(at + 6, "  tf:\n" + tf_block);
}

TfConfig tfOf(const std::string& tf_block) {
  return sl::daemon::parseConfig(withTf(tf_block), "test.yaml").dds.tf;
}

std::string errorOf(const std::string& tf_block) { return sl::test::configErrorOf(withTf(tf_block)); }

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

}  // namespace

TEST_CASE("dds.tf: defaults, mount pose as rpy (tf2's setRPY) or quaternion", "[ros_graph][tf]") {
  const TfConfig defaults = sl::daemon::parseConfig(sl::test::shippedSimConfigText(), "sim.yaml").dds.tf;
  CHECK(defaults.publish);
  CHECK(defaults.parent_frame.empty());
  CHECK(defaults.base_frame == "sl_base_link");
  CHECK(defaults.projector_frame == "sl_projector_optical_frame");

  // yaw 90 deg about z: q = (0, 0, sin 45, cos 45).
  const TfConfig yaw = tfOf("    parent_frame: robot\n    mount: {xyz: [1, 2, 3], rpy: [0, 0, 1.5707963267948966]}\n");
  CHECK(yaw.parent_frame == "robot");
  CHECK(yaw.mount_xyz_m == std::array<double, 3>{1, 2, 3});
  CHECK(yaw.mount_xyzw[0] == Approx(0).margin(1e-12));
  CHECK(yaw.mount_xyzw[1] == Approx(0).margin(1e-12));
  CHECK(yaw.mount_xyzw[2] == Approx(std::sqrt(0.5)));
  CHECK(yaw.mount_xyzw[3] == Approx(std::sqrt(0.5)));

  // roll then pitch (fixed axes): q = q_pitch * q_roll.
  const double r = 0.3, p = -0.4;
  const TfConfig rp = tfOf("    parent_frame: robot\n    mount: {rpy: [0.3, -0.4, 0]}\n");
  CHECK(rp.mount_xyzw[0] == Approx(std::sin(r / 2) * std::cos(p / 2)));
  CHECK(rp.mount_xyzw[1] == Approx(std::cos(r / 2) * std::sin(p / 2)));
  CHECK(rp.mount_xyzw[2] == Approx(-std::sin(r / 2) * std::sin(p / 2)));
  CHECK(rp.mount_xyzw[3] == Approx(std::cos(r / 2) * std::cos(p / 2)));

  // A quaternion within 1e-3 of unit length is normalized.
  const TfConfig q = tfOf("    parent_frame: robot\n    mount: {quaternion: [0, 0, 0, 1.0005]}\n");
  CHECK(q.mount_xyzw[3] == Approx(1.0).epsilon(1e-12));
}

TEST_CASE("dds.tf mistakes are ConfigErrors naming the key", "[ros_graph][tf]") {
  CHECK(contains(errorOf("    mount: {xyz: [0, 0, 1]}\n"), "parent_frame"));
  CHECK(contains(errorOf("    parent_frame: robot\n    mount: {rpy: [0, 0, 0], quaternion: [0, 0, 0, 1]}\n"),
                 "quaternion"));
  const std::string norm = errorOf("    parent_frame: robot\n    mount: {quaternion: [0, 0, 0, 2]}\n");
  CHECK(contains(norm, "quaternion"));
  CHECK(contains(norm, "unit"));
  CHECK(contains(errorOf("    parent_frame: robot\n    mount: {xyz: [0, 1]}\n"), "xyz"));
  CHECK(contains(errorOf("    parent_frame: robot\n    mount: {rpy: [0, .nan, 0]}\n"), "rpy"));
  CHECK(contains(errorOf("    base_frame: /sl_base\n"), "base_frame"));
  CHECK(contains(errorOf("    projector_frame: \"\"\n"), "projector_frame"));
  CHECK(contains(errorOf("    parent_frame: sl_base_link\n"), "parent_frame"));
  CHECK(contains(errorOf("    parnt_frame: robot\n"), "parnt_frame"));
  CHECK(contains(errorOf("    parent_frame: robot\n    mount: {xzy: [0, 0, 0]}\n"), "xzy"));
}

TEST_CASE("sensorTransforms: mount, optical frames of every camera, projector", "[ros_graph][tf]") {
  using sl::daemon::CameraFrame;
  TfConfig tf;
  tf.parent_frame = "robot";
  tf.mount_xyz_m = {0.1, 0.2, 0.3};
  tf.mount_xyzw = {0, 0, std::sqrt(0.5), std::sqrt(0.5)};
  sl::pipeline::CameraProjectorCalibration a, b;
  a.R = Eigen::AngleAxisd(0.26, Eigen::Vector3d::UnitY()).toRotationMatrix();
  a.t = {-145, 0, 39};
  b.R = Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()).toRotationMatrix() *
        Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitX()).toRotationMatrix();
  b.t = {140, 10, 30};
  const std::vector<CameraFrame> cameras{{"left", "left_optical", a}, {"right", "right_optical", b}};
  const auto transforms = sl::daemon::sensorTransforms(tf, cameras);
  REQUIRE(transforms.size() == 4);
  auto find = [&](const std::string& child) {
    for (const auto& t : transforms)
      if (t.child == child) return t;
    FAIL("no transform to " << child);
    return transforms.front();
  };
  const auto mount = find("sl_base_link");
  CHECK(mount.parent == "robot");
  CHECK((mount.pose.translation() - Eigen::Vector3d(0.1, 0.2, 0.3)).norm() < 1e-12);
  CHECK((mount.pose.linear() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm() < 1e-12);

  const auto left = find("left_optical"), right = find("right_optical");
  CHECK(left.parent == "sl_base_link");
  CHECK(right.parent == "sl_base_link");
  // The first camera's optical axis (z) is the base's x, its x (right) the
  // base's -y, its y (down) the base's -z (REP 103).
  CHECK((left.pose.linear() * Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitX()).norm() < 1e-12);
  CHECK((left.pose.linear() * Eigen::Vector3d::UnitX() + Eigen::Vector3d::UnitY()).norm() < 1e-12);
  CHECK((left.pose.linear() * Eigen::Vector3d::UnitY() + Eigen::Vector3d::UnitZ()).norm() < 1e-12);
  CHECK(left.pose.translation().norm() < 1e-12);

  // Both cameras see the projector at one place: its centre, X_c = -R^T t
  // in each camera's frame (mm), lands on the same point of the base frame.
  const Eigen::Vector3d via_left = left.pose * (-(a.R.transpose() * a.t) * 1e-3);
  const Eigen::Vector3d via_right = right.pose * (-(b.R.transpose() * b.t) * 1e-3);
  CHECK((via_left - via_right).norm() < 1e-12);
  const auto projector = find("sl_projector_optical_frame");
  CHECK(projector.parent == "left_optical");
  CHECK(((left.pose * projector.pose).translation() - via_left).norm() < 1e-12);
  // ... and its axes: a projector ray d_p is R^T d_p in the first camera.
  const Eigen::Vector3d ray(0.1, -0.2, 1.0);
  CHECK((projector.pose.linear() * ray - a.R.transpose() * ray).norm() < 1e-12);

  SECTION("no parent frame: no mount transform") {
    tf.parent_frame.clear();
    CHECK(sl::daemon::sensorTransforms(tf, cameras).size() == 3);
  }
  SECTION("two frames with one name are refused") {
    tf.projector_frame = "right_optical";
    try {
      sl::daemon::sensorTransforms(tf, cameras);
      FAIL("no ConfigError");
    } catch (const ConfigError& e) {
      CHECK(contains(e.what(), "dds.tf.projector_frame"));
      CHECK(contains(e.what(), "camera 'right'"));
      CHECK(contains(e.what(), "'right_optical'"));
    }
  }
}

TEST_CASE("dds.tf.mount.hand_eye: the mount from an sl_handeye result", "[ros_graph][tf]") {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("sl_hand_eye_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  // The first camera's optical frame in the flange: a rotation about a
  // skew axis and 12.5 / -40 / 95 mm.
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()));
  const fs::path file = dir / "hand_eye.yaml";
  {
    std::ofstream out(file);
    out.precision(17);
    out << "format: sl-sensor-hand-eye/1\nsetup: eye-in-hand\nmount:\n  translation_mm: [12.5, -40, 95]\n"
        << "  quaternion_xyzw: [" << q.x() << ", " << q.y() << ", " << q.z() << ", " << q.w() << "]\n";
  }
  const TfConfig tf = tfOf("    parent_frame: tool0\n    mount: {hand_eye: " + file.string() + "}\n");
  sl::pipeline::CameraProjectorCalibration calibration;
  calibration.R = Eigen::Matrix3d::Identity();
  calibration.t = {150, 0, 0};
  const auto transforms = sl::daemon::sensorTransforms(tf, {{"cam", "cam_optical", calibration}});
  Eigen::Isometry3d tool0_from_base = Eigen::Isometry3d::Identity(), base_from_optical = tool0_from_base;
  for (const auto& t : transforms) {
    if (t.parent == "tool0" && t.child == "sl_base_link") tool0_from_base = t.pose;
    if (t.parent == "sl_base_link" && t.child == "cam_optical") base_from_optical = t.pose;
  }
  // Through the tree, the optical frame lands where the file put it.
  const Eigen::Isometry3d tool0_from_optical = tool0_from_base * base_from_optical;
  CHECK((tool0_from_optical.translation() - Eigen::Vector3d(0.0125, -0.040, 0.095)).norm() < 1e-12);
  CHECK((tool0_from_optical.linear() - q.toRotationMatrix()).norm() < 1e-9);

  // Mistakes name the key (and the file).
  CHECK(contains(errorOf("    parent_frame: tool0\n    mount: {hand_eye: " + (dir / "missing.yaml").string() + "}\n"),
                 "hand_eye"));
  CHECK(contains(errorOf("    mount: {hand_eye: " + file.string() + "}\n"), "parent_frame"));
  CHECK(contains(errorOf("    parent_frame: tool0\n    mount: {hand_eye: " + file.string() + ", xyz: [0, 0, 0]}\n"),
                 "not both"));
  {
    std::ofstream out(dir / "other.yaml");
    out << "camera: {fx: 1}\n";
  }
  const std::string other = errorOf("    parent_frame: tool0\n    mount: {hand_eye: " + (dir / "other.yaml").string() + "}\n");
  CHECK(contains(other, "hand_eye"));
  CHECK(contains(other, "sl-sensor-hand-eye/1"));
  fs::remove_all(dir);
}

TEST_CASE("diagnosticsOf: levels from the daemon's state", "[ros_graph][diagnostics]") {
  using sl::client::ScanState;
  constexpr std::uint8_t kOk = 0, kWarn = 1, kError = 2;
  sl::daemon::EngineStatus s;
  sl::daemon::DiagnosticInputs in;
  in.node_name = "sl_sensord";
  in.camera_ids = {"left", "right"};
  auto levels = [&] {
    std::vector<int> out;
    for (const auto& d : sl::daemon::diagnosticsOf(s, in)) out.push_back(d.level);
    return out;
  };
  auto value = [](const sl::daemon::Diagnostic& d, const std::string& key) {
    for (const auto& [k, v] : d.values)
      if (k == key) return v;
    return std::string("(none)");
  };

  const auto idle = sl::daemon::diagnosticsOf(s, in);
  REQUIRE(idle.size() == 4);
  CHECK(idle[0].name == "sl_sensord: camera left");
  CHECK(idle[0].hardware_id == "left");
  CHECK(idle[1].name == "sl_sensord: camera right");
  CHECK(idle[2].name == "sl_sensord: trigger source");
  CHECK(idle[3].name == "sl_sensord: pipeline");
  CHECK(levels() == std::vector<int>{kOk, kOk, kOk, kOk});
  CHECK(idle[3].message == "idle");

  s.state = ScanState::kScanning;
  s.pattern = "p";
  s.scan_rate_hz = 5;
  s.scans_done = 12;
  s.frames_dropped = 3;
  const auto scanning = sl::daemon::diagnosticsOf(s, in);
  CHECK(levels() == std::vector<int>{kOk, kOk, kOk, kOk});
  CHECK(scanning[3].message == "scanning p at 5 Hz");
  CHECK(value(scanning[3], "scans_done") == "12");
  CHECK(value(scanning[3], "frames_dropped") == "3");

  SECTION("a points reader that lost clouds: pipeline WARN") {
    in.points_readers.push_back({"1:2:3:4", true, true, 7});
    const auto d = sl::daemon::diagnosticsOf(s, in);
    CHECK(levels() == std::vector<int>{kOk, kOk, kOk, kWarn});
    CHECK(contains(d[3].message, "lost 7 clouds"));
  }
  SECTION("degraded: WARN on the devices the cause names and on the pipeline") {
    s.state = ScanState::kDegraded;
    s.degraded_reason = "camera 'right': no frame for 2.1 s; trigger source: no trigger for 2.1 s";
    const auto d = sl::daemon::diagnosticsOf(s, in);
    CHECK(levels() == std::vector<int>{kOk, kWarn, kWarn, kWarn});
    CHECK(d[1].message == "camera 'right': no frame for 2.1 s");
    CHECK(d[2].message == "trigger source: no trigger for 2.1 s");
    CHECK(contains(d[3].message, s.degraded_reason));
    CHECK(value(d[3], "degraded_reason") == s.degraded_reason);
  }
  SECTION("error: ERROR on the pipeline, and on the device the error names") {
    s.state = ScanState::kError;
    s.last_error = "camera 'left': stream lost";
    const auto d = sl::daemon::diagnosticsOf(s, in);
    CHECK(levels() == std::vector<int>{kError, kOk, kOk, kError});
    CHECK(d[0].message == "camera 'left': stream lost");
    CHECK(d[3].message == "camera 'left': stream lost");
  }
}
