// In-field verification and projector pose correction on the simulator
// (issue 35 item 2): the projector moved by known amounts against the
// calibration, detected above the verification's threshold, and corrected to
// within the stated uncertainty.
#include <catch2/catch.hpp>

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
#include <utility>

#include "board_sim.h"
#include "sl/files/calibration_io.h"
#include "sl/drivers/sim_rig.h"
#include "sl/pipeline/calibration_check.h"

namespace {

using metrology_test::BoardPose;
using metrology_test::degrees;
using metrology_test::radians;
using sl::pipeline::CameraProjectorCalibration;
using sl::pipeline::Checkerboard;

const Checkerboard kBoard{13, 9, 15.0};

// Corner noise of the synthetic views: twice what the full simulator chain
// gives (test_hand_eye's rendered case prints ~0.027 px for both devices).
constexpr double kCameraNoisePx = 0.05, kProjectorNoisePx = 0.05;

// Three board views, as a user holds the board for a field check.
const std::vector<BoardPose> kViews = {
    {0, 0, 0, {0, 0, 560}}, {20, -15, 10, {0, 0, 600}}, {-15, 20, -10, {10, 0, 530}}};

// The rig with its projector moved: turned by `rotation_deg` about `axis`
// (projector frame) and shifted by `shift_mm` (projector frame).
CameraProjectorCalibration moved(const CameraProjectorCalibration& rig, double rotation_deg,
                                 const Eigen::Vector3d& axis, const Eigen::Vector3d& shift_mm) {
  CameraProjectorCalibration m = rig;
  const Eigen::Matrix3d d = Eigen::AngleAxisd(radians(rotation_deg), axis.normalized()).toRotationMatrix();
  m.R = d * rig.R;
  m.t = d * rig.t + shift_mm;
  return m;
}

struct Move {
  const char* name;
  double rotation_deg;
  Eigen::Vector3d axis, shift_mm;
};

}  // namespace

TEST_CASE("verification: known projector moves detected, the unmoved rig passes; correction "
          "undoes them within its uncertainty",
          "[metrology][verify]") {
  const CameraProjectorCalibration rig = sl::drivers::simRig();
  const std::vector<Move> moves = {
      {"none", 0, {0, 1, 0}, {0, 0, 0}},
      {"0.1 deg about y", 0.1, {0, 1, 0}, {0, 0, 0}},
      {"0.1 deg about x", 0.1, {1, 0, 0}, {0, 0, 0}},
      {"1 deg about z", 1.0, {0, 0, 1}, {0, 0, 0}},
      {"0.2 mm along x", 0, {0, 1, 0}, {0.2, 0, 0}},
      {"0.2 mm along y", 0, {0, 1, 0}, {0, 0.2, 0}},
      {"2 mm along z", 0, {0, 1, 0}, {0, 0, 2.0}},
      {"0.5 deg + 1 mm", 0.5, {1, 1, 0}, {1.0, -0.5, 0.3}},
  };
  const sl::pipeline::VerificationThresholds thresholds;
  std::mt19937_64 rng(77);
  double z_sq = 0;
  int z_count = 0;
  for (const Move& move : moves) {
    const CameraProjectorCalibration truth = moved(rig, move.rotation_deg, move.axis, move.shift_mm);
    std::vector<sl::pipeline::BoardView> views;
    for (std::size_t i = 0; i < kViews.size(); ++i)
      views.push_back(metrology_test::syntheticView(
          truth, kBoard, metrology_test::cameraFromBoard(kBoard, kViews[i]), kCameraNoisePx, kProjectorNoisePx, rng,
          "view" + std::to_string(i)));
    const auto check = sl::pipeline::verifyCalibration(rig, views, kBoard, thresholds);
    const auto fix = sl::pipeline::correctProjectorPose(rig, views, kBoard);
    // The corrected rig against the truth, in the correction's parameters:
    // rotation about the projector's axes, translation of t.
    const Eigen::AngleAxisd dr(truth.R * fix.calibration.R.transpose());
    const Eigen::Vector3d w = degrees(dr.angle()) * dr.axis();
    const Eigen::Vector3d dt = fix.calibration.t - truth.t;
    const auto recheck = sl::pipeline::verifyCalibration(fix.calibration, views, kBoard, thresholds);
    std::printf(
        "verify %-16s consistency %.3f mm (%.2f px), square %+.4f mm, flatness %.3f mm -> %s; "
        "corrected: off by %.4f deg (1-sigma %.4f), %.4f mm (1-sigma %.4f); recheck %.3f mm\n",
        move.name, check.consistency_rms_mm, check.views[0].consistency_rms_px,
        check.square_error_mm, check.flatness_rms_mm, check.pass ? "pass" : "FAIL", w.norm(),
        fix.sigma_rotation_deg.norm(), dt.norm(), fix.sigma_translation_mm.norm(),
        recheck.consistency_rms_mm);
    INFO(move.name);
    if (move.rotation_deg == 0 && move.shift_mm.norm() == 0) {
      CHECK(check.pass);
      CHECK(check.failures.empty());
    } else {
      CHECK_FALSE(check.pass);
      CHECK(check.consistency_rms_mm > thresholds.max_consistency_rms_mm);
      CHECK(fix.rotation_change_deg > 0.5 * move.rotation_deg);
    }
    CHECK(recheck.pass);
    for (int q = 0; q < 3; ++q) {
      CHECK(std::abs(w(q)) < 3 * fix.sigma_rotation_deg(q));
      CHECK(std::abs(dt(q)) < 3 * fix.sigma_translation_mm(q));
      z_sq += std::pow(w(q) / fix.sigma_rotation_deg(q), 2) +
              std::pow(dt(q) / fix.sigma_translation_mm(q), 2);
      z_count += 2;
    }
    // A useful correction: well below the smallest move tested.
    CHECK(fix.sigma_rotation_deg.norm() < 0.02);
    CHECK(fix.sigma_translation_mm.norm() < 0.1);
  }
  const double z_rms = std::sqrt(z_sq / z_count);
  std::printf("correction error / stated 1-sigma: RMS %.2f over %d parameters\n", z_rms, z_count);
  CHECK(z_rms < 1.5);
  CHECK(z_rms > 0.5);
}

TEST_CASE("verification: too few corners are refused", "[metrology][verify]") {
  const CameraProjectorCalibration rig = sl::drivers::simRig();
  std::mt19937_64 rng(1);
  auto v = metrology_test::syntheticView(rig, kBoard, metrology_test::cameraFromBoard(kBoard, kViews[0]),
                                         0.1, 0.15, rng, "v");
  v.corner_ids.resize(5);
  v.camera_px.resize(5);
  v.projector_px.resize(5);
  CHECK_THROWS_AS(sl::pipeline::verifyCalibration(rig, {v}, kBoard), std::invalid_argument);
  CHECK_THROWS_AS(sl::pipeline::correctProjectorPose(rig, {}, kBoard), std::invalid_argument);
}

namespace {

// Runs a tool of the build; exit code and its output (stdout and stderr).
std::pair<int, std::string> runTool(const std::string& args, const std::filesystem::path& log) {
  const std::string command =
      std::string(SL_BINARY_DIR) + "/tools/" + args + " > " + log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text};
}

}  // namespace

TEST_CASE("sl_verify: rendered scans with a moved projector fail; --correct writes a new "
          "calibration that passes",
          "[metrology][verify]") {
  namespace fs = std::filesystem;
  const CameraProjectorCalibration rig = sl::drivers::simRig();
  // The projector knocked by 0.2 deg about its y axis and 0.5 mm sideways.
  const CameraProjectorCalibration truth = moved(rig, 0.2, {0, 1, 0}, {0.5, 0, 0});
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_metrology_verify";
  fs::remove_all(dir);
  fs::create_directories(dir);
  sl::files::CalibrationFile file;
  file.calibration = rig;
  file.source = "test_metrology: the simulator's rig before the knock";
  sl::files::saveCalibration(file, (dir / "calibration.yaml").string());
  sl::pipeline::PhaseShift33Pattern pattern;
  pattern.name = "3+3_both";
  pattern.direction = sl::pipeline::Direction::kBoth;
  const sl::pipeline::PatternSpec spec = sl::pipeline::toSpec(pattern);
  std::string folders;
  for (std::size_t i = 0; i < kViews.size(); ++i) {
    sl::drivers::SimConfig config;
    config.rig = truth;
    config.patterns = {spec};
    config.scene.planes = {metrology_test::boardPlane(kBoard, metrology_test::cameraFromBoard(kBoard, kViews[i]))};
    const auto sensor = sl::drivers::SimulatedSensor::create(config);
    const fs::path folder = dir / ("view" + std::to_string(i));
    fs::create_directories(folder);
    for (int f = 0; f < spec.frameCount(); ++f)
      REQUIRE(cv::imwrite((folder / ("frame_" + std::to_string(f) + ".png")).string(),
                          sensor->render(spec.name, f, 300 * i + f + 1)));
    folders += " " + folder.string();
  }
  const std::string common = " --board 13x9 --square 15 --presmooth 1 --window-radius 25 --scans" + folders;
  const auto [code, output] =
      runTool("sl_verify --calibration " + (dir / "calibration.yaml").string() + " --correct " +
                  (dir / "corrected.yaml").string() + common,
              dir / "verify.log");
  INFO(output);
  CHECK(code == 4);  // the given calibration does not hold
  CHECK(output.find("-> FAIL") != std::string::npos);
  CHECK(output.find("camera-projector consistency") != std::string::npos);
  REQUIRE(fs::exists(dir / "corrected.yaml"));
  const CameraProjectorCalibration corrected =
      sl::files::loadCalibration((dir / "corrected.yaml").string()).calibration;
  const double rotation_deg = degrees(Eigen::AngleAxisd(truth.R * corrected.R.transpose()).angle());
  const double translation_mm = (corrected.t - truth.t).norm();
  std::printf("sl_verify --correct on 3 rendered views (projector moved 0.2 deg, 0.5 mm): corrected "
              "to %.4f deg, %.4f mm of the truth\n",
              rotation_deg, translation_mm);
  CHECK(rotation_deg < 0.01);
  CHECK(translation_mm < 0.1);
  // The corrected calibration on the same scans passes.
  const auto [code2, output2] =
      runTool("sl_verify --calibration " + (dir / "corrected.yaml").string() + common,
              dir / "verify2.log");
  INFO(output2);
  CHECK(code2 == 0);
  CHECK(output2.find("-> PASS") != std::string::npos);
  // Never over an existing file.
  const auto [code3, output3] =
      runTool("sl_verify --calibration " + (dir / "calibration.yaml").string() + " --correct " +
                  (dir / "calibration.yaml").string() + common,
              dir / "verify3.log");
  CHECK(code3 == 1);
  CHECK(output3.find("the file exists") != std::string::npos);
}
