// Hand-eye calibration on the simulator (issue 35 item 1): robot poses
// generated around a known mount, board scans at each pose, the mount's
// error against the truth and its stated 1-sigma.
#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "board_sim.h"
#include "sl/files/calibration_io.h"
#include "sl/drivers/sim_rig.h"
#include "sl/pipeline/hand_eye.h"

namespace {

using metrology_test::BoardPose;
using metrology_test::degrees;
using metrology_test::radians;
using sl::pipeline::Checkerboard;
using sl::pipeline::HandEyeView;

const Checkerboard kBoard{13, 9, 15.0};

// Where the camera sees the board from, one entry per robot pose: tilts about
// both axes and spins, 520..660 mm (the first five already span both axes).
const std::vector<BoardPose> kViews = {
    {0, 0, 0, {0, 0, 560}},       {25, 0, 10, {0, 0, 580}},      {0, 25, -10, {10, 0, 560}},
    {-20, -15, 20, {0, 10, 600}}, {15, -25, -20, {-10, 0, 540}}, {-25, 5, 0, {0, -10, 620}},
    {5, -20, 30, {15, 0, 590}},   {20, 20, -30, {0, 0, 640}},    {-15, 20, 15, {-15, 5, 530}},
    {10, 10, 45, {0, 0, 600}},    {-10, -25, -45, {5, 5, 610}},  {28, -8, 5, {0, 0, 570}},
    {-28, 8, -5, {0, 0, 570}},    {8, 28, 25, {10, 10, 620}},    {-8, -28, -25, {-10, -10, 620}},
    {18, -18, 60, {0, 0, 650}},   {-18, 18, -60, {0, 0, 550}},   {0, 0, 90, {0, 0, 600}},
    {12, 22, -15, {5, -5, 560}},  {-22, -12, 15, {-5, 5, 640}},
};

struct Truth {
  Eigen::Isometry3d mount;   // eye-in-hand: gripper_from_camera; eye-to-hand: base_from_camera
  Eigen::Isometry3d target;  // eye-in-hand: base_from_board; eye-to-hand: gripper_from_board
};

Truth truthFor(sl::pipeline::HandEyeSetup setup) {
  Truth t;
  t.mount = Eigen::Isometry3d::Identity();
  t.target = Eigen::Isometry3d::Identity();
  if (setup == sl::pipeline::HandEyeSetup::kEyeInHand) {
    // The sensor 120 mm below the flange, offset and turned.
    t.mount.linear() = (Eigen::AngleAxisd(radians(12), Eigen::Vector3d(0.3, -1, 0.2).normalized()) *
                        Eigen::AngleAxisd(radians(90), Eigen::Vector3d::UnitZ()))
                           .toRotationMatrix();
    t.mount.translation() = Eigen::Vector3d(35, -60, 120);
    t.target.linear() = Eigen::AngleAxisd(radians(170), Eigen::Vector3d::UnitX()).toRotationMatrix();
    t.target.translation() = Eigen::Vector3d(650, 120, 40);
  } else {
    // The sensor fixed above the cell, the board on the flange.
    t.mount.linear() = Eigen::AngleAxisd(radians(160), Eigen::Vector3d(1, 0.2, 0).normalized())
                           .toRotationMatrix();
    t.mount.translation() = Eigen::Vector3d(500, -100, 1100);
    t.target.linear() = Eigen::AngleAxisd(radians(-8), Eigen::Vector3d::UnitY()).toRotationMatrix();
    t.target.translation() = Eigen::Vector3d(-60, -40, 95);
  }
  return t;
}

// The robot pose (base_from_gripper) that puts the camera at camera_from_board.
Eigen::Isometry3d robotPose(sl::pipeline::HandEyeSetup setup, const Truth& t,
                            const Eigen::Isometry3d& camera_from_board) {
  if (setup == sl::pipeline::HandEyeSetup::kEyeInHand)
    return t.target * camera_from_board.inverse() * t.mount.inverse();
  return t.mount * camera_from_board * t.target.inverse();
}

struct Errors {
  double rotation_deg = 0, translation_mm = 0;
  double sigma_rotation_deg = 0, sigma_translation_mm = 0;  // root sum of squares of the axes'
  Eigen::Matrix<double, 6, 1> z;  // per parameter, error / sigma
};

Errors errorsOf(const sl::pipeline::HandEyeResult& r, const Truth& t) {
  Errors e;
  const Eigen::AngleAxisd d(t.mount.linear().transpose() * r.mount.linear());  // mount frame
  const Eigen::Vector3d w = d.angle() * d.axis();
  const Eigen::Vector3d dt = r.mount.translation() - t.mount.translation();
  e.rotation_deg = degrees(w.norm());
  e.translation_mm = dt.norm();
  e.sigma_rotation_deg = r.sigma_rotation_deg.norm();
  e.sigma_translation_mm = r.sigma_translation_mm.norm();
  for (int q = 0; q < 3; ++q) {
    e.z(q) = degrees(w(q)) / r.sigma_rotation_deg(q);
    e.z(3 + q) = dt(q) / r.sigma_translation_mm(q);
  }
  return e;
}

// Views of the first n poses of kViews with corners from `observe`.
template <typename Observe>
std::vector<HandEyeView> handEyeViews(sl::pipeline::HandEyeSetup setup, const Truth& truth, int n,
                                      const sl::pipeline::CameraProjectorCalibration& rig,
                                      Observe observe) {
  std::vector<HandEyeView> views;
  for (int i = 0; i < n; ++i) {
    const Eigen::Isometry3d camera_from_board = metrology_test::cameraFromBoard(kBoard, kViews[i]);
    const sl::pipeline::BoardView board_view = observe(i, camera_from_board);
    HandEyeView v;
    v.label = "pose" + std::to_string(i);
    v.base_from_gripper = robotPose(setup, truth, camera_from_board);
    v.corner_ids = board_view.corner_ids;
    v.points_mm = sl::pipeline::triangulateBoardCorners(rig, board_view);
    views.push_back(v);
  }
  return views;
}

}  // namespace

TEST_CASE("hand-eye: eye-in-hand on rendered scans meets the targets with 10 poses",
          "[metrology][hand_eye]") {
  const auto start = std::chrono::steady_clock::now();
  const auto setup = sl::pipeline::HandEyeSetup::kEyeInHand;
  const Truth truth = truthFor(setup);
  const sl::pipeline::CameraProjectorCalibration rig = sl::drivers::simRig();
  // The observations' noise against the true projections (it sets the
  // synthetic noise of the other tests).
  double camera_sq = 0, projector_sq = 0;
  std::size_t corners = 0;
  const auto views = handEyeViews(setup, truth, 10, rig, [&](int i, const Eigen::Isometry3d& T) {
    std::string error;
    const auto v = metrology_test::renderedView(rig, kBoard, T, 100 + i, "pose" + std::to_string(i),
                                                &error);
    INFO(error);
    REQUIRE(v.corner_ids.size() >= 100);
    for (std::size_t k = 0; k < v.corner_ids.size(); ++k) {
      const cv::Point3f b = kBoard.corner(v.corner_ids[k]);
      const Eigen::Vector3d X = T * Eigen::Vector3d(b.x, b.y, b.z);
      camera_sq += (rig.camera.project(X) - Eigen::Vector2d(v.camera_px[k].x, v.camera_px[k].y))
                       .squaredNorm();
      projector_sq += (rig.projector.project(rig.R * X + rig.t) -
                       Eigen::Vector2d(v.projector_px[k].x, v.projector_px[k].y))
                          .squaredNorm();
      ++corners;
    }
    return v;
  });
  std::printf("rendered corners: camera %.4f px, projector %.4f px RMS (per point, 2D)\n",
              std::sqrt(camera_sq / corners), std::sqrt(projector_sq / corners));
  const auto r = sl::pipeline::calibrateHandEye(views, kBoard, setup);
  const Errors e = errorsOf(r, truth);
  const Eigen::AngleAxisd start_error(truth.mount.linear().transpose() * r.initial_mount.linear());
  std::printf(
      "hand-eye rendered, 10 poses (%.1f s): rotation error %.4f deg (1-sigma %.4f), translation "
      "%.4f mm (1-sigma %.4f); Tsai start %.4f deg %.4f mm; corner RMS %.4f mm\n",
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
      e.rotation_deg, e.sigma_rotation_deg, e.translation_mm, e.sigma_translation_mm,
      degrees(start_error.angle()),
      (r.initial_mount.translation() - truth.mount.translation()).norm(), r.rms_mm);
  for (const auto& a : r.advice) std::printf("  advice: %s\n", a.c_str());
  // Issue 35's targets at the simulator's noise with 10 poses.
  CHECK(e.rotation_deg < 0.05);
  CHECK(e.translation_mm < 0.2);
  // The stated uncertainty covers the error (3-sigma per parameter: one trial).
  for (int q = 0; q < 6; ++q) CHECK(std::abs(e.z(q)) < 3.0);
  CHECK(r.view_rms_mm.size() == 10);
}

TEST_CASE("hand-eye: 5, 10, 20 poses over noise seeds, eye-in-hand and eye-to-hand; 1-sigma "
          "calibrated",
          "[metrology][hand_eye]") {
  const sl::pipeline::CameraProjectorCalibration rig = sl::drivers::simRig();
  for (const auto setup :
       {sl::pipeline::HandEyeSetup::kEyeInHand, sl::pipeline::HandEyeSetup::kEyeToHand}) {
    const Truth truth = truthFor(setup);
    const char* name = setup == sl::pipeline::HandEyeSetup::kEyeInHand ? "eye-in-hand" : "eye-to-hand";
    // Eye-to-hand sees the same observations (the camera's board poses are
    // the same): one pose count is enough to check its own bookkeeping.
    const std::vector<int> counts =
        setup == sl::pipeline::HandEyeSetup::kEyeInHand ? std::vector<int>{5, 10, 20}
                                                        : std::vector<int>{10};
    for (const int n : counts) {
      constexpr int kTrials = 25;
      std::mt19937_64 rng(1234 + n);
      double rot_sq = 0, trans_sq = 0, rot_sigma = 0, trans_sigma = 0, z_sq = 0, rot_max = 0,
             trans_max = 0;
      int within = 0;
      for (int trial = 0; trial < kTrials; ++trial) {
        const auto views = handEyeViews(setup, truth, n, rig, [&](int i, const Eigen::Isometry3d& T) {
          return metrology_test::syntheticView(rig, kBoard, T, 0.1, 0.15, rng,
                                               "pose" + std::to_string(i));
        });
        const Errors e = errorsOf(sl::pipeline::calibrateHandEye(views, kBoard, setup), truth);
        rot_sq += e.rotation_deg * e.rotation_deg;
        trans_sq += e.translation_mm * e.translation_mm;
        rot_max = std::max(rot_max, e.rotation_deg);
        trans_max = std::max(trans_max, e.translation_mm);
        rot_sigma += e.sigma_rotation_deg;
        trans_sigma += e.sigma_translation_mm;
        z_sq += e.z.squaredNorm();
        for (int q = 0; q < 6; ++q) within += std::abs(e.z(q)) <= 1.0;
      }
      const double z_rms = std::sqrt(z_sq / (6.0 * kTrials));
      const double coverage = double(within) / (6.0 * kTrials);
      std::printf(
          "hand-eye %s, %2d poses, %d seeds: rotation error RMS %.4f max %.4f deg (stated 1-sigma "
          "%.4f), translation RMS %.4f max %.4f mm (stated %.4f); error/sigma RMS %.2f, "
          "|error| <= 1-sigma in %.0f %% (68 %% expected)\n",
          name, n, kTrials, std::sqrt(rot_sq / kTrials), rot_max, rot_sigma / kTrials,
          std::sqrt(trans_sq / kTrials), trans_max, trans_sigma / kTrials, z_rms, 100 * coverage);
      INFO(name << " with " << n << " poses");
      // The stated 1-sigma is the error's scale: neither optimistic nor
      // inflated by more than 1.5x.
      CHECK(z_rms < 1.3);
      CHECK(z_rms > 0.6);
      if (n >= 10) {
        CHECK(rot_max < 0.05);
        CHECK(trans_max < 0.2);
      }
    }
  }
}

TEST_CASE("hand-eye: a wrong robot pose is named, degenerate motions are refused",
          "[metrology][hand_eye]") {
  const auto setup = sl::pipeline::HandEyeSetup::kEyeInHand;
  const Truth truth = truthFor(setup);
  const sl::pipeline::CameraProjectorCalibration rig = sl::drivers::simRig();
  std::mt19937_64 rng(9);
  auto views = handEyeViews(setup, truth, 10, rig, [&](int i, const Eigen::Isometry3d& T) {
    return metrology_test::syntheticView(rig, kBoard, T, 0.1, 0.15, rng, "pose" + std::to_string(i));
  });
  // Pose 6 recorded 2 deg off (the robot moved before the scan).
  views[6].base_from_gripper.linear() =
      views[6].base_from_gripper.linear() *
      Eigen::AngleAxisd(radians(2), Eigen::Vector3d::UnitX()).toRotationMatrix();
  const auto r = sl::pipeline::calibrateHandEye(views, kBoard, setup);
  bool named = false;
  for (const auto& a : r.advice) named = named || a.find("view pose6 ") != std::string::npos;
  INFO(r.advice.size() << " advice lines");
  CHECK(named);

  // Pure translations and rotations about one axis only: refused.
  std::vector<HandEyeView> one_axis;
  for (int i = 0; i < 5; ++i) {
    const BoardPose p{0, 0, 10.0 * i, {0, 0, 600}};
    const Eigen::Isometry3d T = metrology_test::cameraFromBoard(kBoard, p);
    const auto v = metrology_test::syntheticView(rig, kBoard, T, 0.1, 0.15, rng, "p");
    one_axis.push_back({"p" + std::to_string(i), robotPose(setup, truth, T), v.corner_ids,
                        sl::pipeline::triangulateBoardCorners(rig, v)});
  }
  CHECK_THROWS_AS(sl::pipeline::calibrateHandEye(one_axis, kBoard, setup), std::invalid_argument);
  one_axis.resize(2);
  CHECK_THROWS_AS(sl::pipeline::calibrateHandEye(one_axis, kBoard, setup), std::invalid_argument);
}

TEST_CASE("sl_handeye: robot poses file + rendered pose folders -> the mount", "[metrology][hand_eye]") {
  namespace fs = std::filesystem;
  const auto setup = sl::pipeline::HandEyeSetup::kEyeInHand;
  const Truth truth = truthFor(setup);
  const sl::pipeline::CameraProjectorCalibration rig = sl::drivers::simRig();
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_metrology_handeye";
  fs::remove_all(dir);
  fs::create_directories(dir);
  sl::files::CalibrationFile calibration;
  calibration.calibration = rig;
  calibration.source = "test_metrology: the simulator's rig";
  sl::files::saveCalibration(calibration, (dir / "calibration.yaml").string());
  // Four scans: the fewest that rotate about two axes with some margin.
  sl::pipeline::PhaseShift33Pattern pattern;
  pattern.name = "3+3_both";
  pattern.direction = sl::pipeline::Direction::kBoth;
  const sl::pipeline::PatternSpec spec = sl::pipeline::toSpec(pattern);
  std::ofstream poses(dir / "poses.txt");
  poses << "# folder x y z qx qy qz qw (base_from_gripper, mm)\n";
  for (int i = 0; i < 4; ++i) {
    const Eigen::Isometry3d T = metrology_test::cameraFromBoard(kBoard, kViews[i]);
    sl::drivers::SimConfig config;
    config.rig = rig;
    config.patterns = {spec};
    config.scene.planes = {metrology_test::boardPlane(kBoard, T)};
    const auto sensor = sl::drivers::SimulatedSensor::create(config);
    const fs::path folder = dir / ("pose" + std::to_string(i));
    fs::create_directories(folder);
    for (int f = 0; f < spec.frameCount(); ++f)
      REQUIRE(cv::imwrite((folder / ("frame_" + std::to_string(f) + ".png")).string(),
                          sensor->render(spec.name, f, 7000 + 100 * i + f)));
    const Eigen::Isometry3d A = robotPose(setup, truth, T);
    const Eigen::Quaterniond q(A.linear());
    char line[256];
    std::snprintf(line, sizeof line, "pose%d %.6f %.6f %.6f %.12f %.12f %.12f %.12f\n", i,
                  A.translation().x(), A.translation().y(), A.translation().z(), q.x(), q.y(), q.z(),
                  q.w());
    poses << line;
  }
  poses.close();
  const std::string command = std::string(SL_BINARY_DIR) + "/tools/sl_handeye --calibration " +
                              (dir / "calibration.yaml").string() + " --robot-poses " +
                              (dir / "poses.txt").string() +
                              " --board 13x9 --square 15 --presmooth 1 --window-radius 25 --out " +
                              (dir / "mount.yaml").string() + " > " + (dir / "log.txt").string() +
                              " 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream log(dir / "log.txt");
  const std::string output((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  INFO(output);
  REQUIRE(WIFEXITED(status));
  REQUIRE(WEXITSTATUS(status) == 0);
  // The mount as written.
  std::ifstream yaml(dir / "mount.yaml");
  std::string text((std::istreambuf_iterator<char>(yaml)), std::istreambuf_iterator<char>());
  auto mount = text.find("\nmount:\n");
  REQUIRE(mount != std::string::npos);
  ++mount;
  double t[3], q[4];
  REQUIRE(std::sscanf(text.c_str() + mount,
                      "mount:\n  translation_mm: [%lf, %lf, %lf]\n  quaternion_xyzw: [%lf, %lf, %lf, %lf]",
                      &t[0], &t[1], &t[2], &q[0], &q[1], &q[2], &q[3]) == 7);
  const Eigen::Quaterniond written(q[3], q[0], q[1], q[2]);
  const double rotation_deg =
      degrees(Eigen::AngleAxisd(truth.mount.linear().transpose() * written.toRotationMatrix()).angle());
  const double translation_mm = (Eigen::Vector3d(t[0], t[1], t[2]) - truth.mount.translation()).norm();
  std::printf("sl_handeye, 4 rendered poses: rotation error %.4f deg, translation %.4f mm\n",
              rotation_deg, translation_mm);
  CHECK(rotation_deg < 0.05);
  CHECK(translation_mm < 0.2);
  CHECK(text.find("setup: eye-in-hand") != std::string::npos);
  CHECK(text.find("4 views: 10 or more") != std::string::npos);  // advice to add poses

  // A malformed poses line is refused, naming the file and the line.
  std::ofstream bad(dir / "bad.txt");
  bad << "pose0 1 2 3 0 0 0\n";
  bad.close();
  const std::string bad_command = std::string(SL_BINARY_DIR) + "/tools/sl_handeye --calibration " +
                                  (dir / "calibration.yaml").string() + " --robot-poses " +
                                  (dir / "bad.txt").string() + " --board 13x9 --square 15 > " +
                                  (dir / "bad.log").string() + " 2>&1";
  const int bad_status = std::system(bad_command.c_str());
  std::ifstream bad_log(dir / "bad.log");
  const std::string bad_output((std::istreambuf_iterator<char>(bad_log)),
                               std::istreambuf_iterator<char>());
  CHECK(WEXITSTATUS(bad_status) == 1);
  CHECK(bad_output.find("bad.txt:1: expected FOLDER x y z qx qy qz qw") != std::string::npos);
}

TEST_CASE("hand-eye: robot pose errors are covered by the view-clustered 1-sigma",
          "[metrology][hand_eye]") {
  // Each recorded flange pose off by a random 0.1 mm and 0.01 deg (per axis,
  // 1-sigma): an industrial arm's absolute accuracy is of this order or worse.
  const auto setup = sl::pipeline::HandEyeSetup::kEyeInHand;
  const Truth truth = truthFor(setup);
  const sl::pipeline::CameraProjectorCalibration rig = sl::drivers::simRig();
  constexpr int kTrials = 25, kPoses = 10;
  constexpr double kRobotMm = 0.1, kRobotDeg = 0.01;
  std::mt19937_64 rng(4242);
  std::normal_distribution<double> unit(0, 1);
  double z_sq = 0, rot_sq = 0, trans_sq = 0;
  int within = 0;
  for (int trial = 0; trial < kTrials; ++trial) {
    auto views = handEyeViews(setup, truth, kPoses, rig, [&](int i, const Eigen::Isometry3d& T) {
      return metrology_test::syntheticView(rig, kBoard, T, 0.05, 0.05, rng, "pose" + std::to_string(i));
    });
    for (auto& v : views) {
      const Eigen::Vector3d w(unit(rng), unit(rng), unit(rng));
      v.base_from_gripper.linear() =
          v.base_from_gripper.linear() *
          Eigen::AngleAxisd(radians(kRobotDeg) * w.norm(), w.normalized()).toRotationMatrix();
      v.base_from_gripper.translation() += kRobotMm * Eigen::Vector3d(unit(rng), unit(rng), unit(rng));
    }
    const Errors e = errorsOf(sl::pipeline::calibrateHandEye(views, kBoard, setup), truth);
    z_sq += e.z.squaredNorm();
    rot_sq += e.rotation_deg * e.rotation_deg;
    trans_sq += e.translation_mm * e.translation_mm;
    for (int q = 0; q < 6; ++q) within += std::abs(e.z(q)) <= 1.0;
  }
  const double z_rms = std::sqrt(z_sq / (6.0 * kTrials));
  std::printf("hand-eye with robot pose errors (%.2f mm, %.3f deg per axis), %d poses, %d seeds: "
              "rotation error RMS %.4f deg, translation RMS %.4f mm; error/sigma RMS %.2f, within "
              "1-sigma %.0f %%\n",
              kRobotMm, kRobotDeg, kPoses, kTrials, std::sqrt(rot_sq / kTrials),
              std::sqrt(trans_sq / kTrials), z_rms, 100.0 * within / (6.0 * kTrials));
  CHECK(z_rms < 1.5);
  CHECK(z_rms > 0.5);
}
