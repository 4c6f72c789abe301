// Camera-projector calibration: on SLStudio's real captures against its
// published calibration, and a round trip on the simulated sensor with a
// checkerboard-textured plane in known poses.
#include <sys/wait.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "sl/files/calibration_io.h"
#include "sl/files/pattern_config.h"
#include "sl/drivers/sim.h"
#include "sl/drivers/sim_rig.h"
#include "sl/pipeline/calibration.h"
#include "sl/pipeline/decoder.h"
#include "sl_process/process.h"

namespace {

namespace fs = std::filesystem;
using sl::pipeline::BoardView;
using sl::pipeline::CalibrationOptions;
using sl::pipeline::CalibrationResult;
using sl::pipeline::Checkerboard;
using sl::pipeline::PhaseShift33Decoder;
using sl::pipeline::PhaseShift33Pattern;

double degreesBetween(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / std::numbers::pi;
}

double percent(double value, double reference) { return 100.0 * (value - reference) / reference; }

const fs::path kSkull = fs::path(SL_SHARED_DATA_DIR) / "slstudio-skull";

PhaseShift33Pattern slStudioCalibrationPattern() {
  PhaseShift33Pattern p;
  p.name = "3+3_both";
  p.direction = sl::pipeline::Direction::kBoth;
  p.projector_width = 1824;
  p.projector_height = 1140;
  p.fringes = 16;
  return p;
}

// Frames 0-5 columns, 6-11 rows (README of the data set).
BoardView observeSlStudioPose(const std::string& pose, const Checkerboard& board) {
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 12; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%02d.png", i);
    frames.push_back(
        cv::imread((kSkull / "calibration" / pose / name).string(), cv::IMREAD_GRAYSCALE));
    REQUIRE(!frames.back().empty());
  }
  const PhaseShift33Decoder decoder(slStudioCalibrationPattern(), {});
  const sl::pipeline::ProjectorMaps maps = decoder.decode(frames, 8);
  const auto result =
      sl::pipeline::observeBoard(sl::pipeline::meanImage(frames), maps, board, pose, {}, {});
  INFO(result.error);
  REQUIRE(result.view);
  return *result.view;
}

// Mean distance (mm) between neighbouring corners of `view` triangulated with
// `c`: the camera ray of each corner cut with the plane of its projector
// column (projector distortion applied, as the calibration models it).
double triangulatedSquareMm(const sl::pipeline::CameraProjectorCalibration& c,
                            const BoardView& view, const Checkerboard& board) {
  std::vector<Eigen::Vector3d> X(board.cornerCount(), Eigen::Vector3d::Constant(NAN));
  for (std::size_t k = 0; k < view.corner_ids.size(); ++k) {
    const Eigen::Vector2d xc =
        c.camera.pixelToNormalized({view.camera_px[k].x, view.camera_px[k].y});
    const double up =
        c.projector.pixelToNormalized({view.projector_px[k].x, view.projector_px[k].y}).x();
    const Eigen::Vector3d ray(xc.x(), xc.y(), 1.0);
    // X = s * ray with (R X + t).x = up * (R X + t).z
    const double s = (up * c.t.z() - c.t.x()) / (c.R.row(0).dot(ray) - up * c.R.row(2).dot(ray));
    X[view.corner_ids[k]] = s * ray;
  }
  double sum = 0;
  int n = 0;
  for (int id = 0; id < board.cornerCount(); ++id) {
    for (int next : {id % board.cols + 1 < board.cols ? id + 1 : -1,
                     id + board.cols < board.cornerCount() ? id + board.cols : -1}) {
      if (next < 0 || !std::isfinite(X[id].z()) || !std::isfinite(X[next].z())) continue;
      sum += (X[next] - X[id]).norm();
      ++n;
    }
  }
  return n > 0 ? sum / n : NAN;
}

}  // namespace

TEST_CASE("real captures: SLStudio calibration poses reproduce calibration.xml",
          "[calibration][real]") {
  if (!fs::exists(kSkull / "calibration")) {
    WARN("shared data not found at " << kSkull << ": skipped");
    return;
  }
  const auto start = std::chrono::steady_clock::now();
  const Checkerboard board{13, 9, 10.0};
  std::vector<BoardView> views;
  for (const char* pose : {"seq1", "seq3", "seq4", "seq5", "seq6"})
    views.push_back(observeSlStudioPose(pose, board));

  CalibrationOptions options;
  // The camera model of calibration.xml: principal point fixed at the image
  // centre, fx = fy, k1 only (its kc holds k1 alone). The projector gets the
  // tool's default full model.
  options.camera.fix_principal_point = true;
  options.camera.fix_aspect_ratio = true;
  options.camera.radial_terms = 1;
  options.camera.tangential = false;
  const CalibrationResult r = sl::pipeline::calibrateCameraProjector(
      views, board, cv::Size(1688, 1352), cv::Size(1824, 1140), options);
  const auto published = sl::files::loadCalibration((kSkull / "calibration.xml").string());
  const auto& ref = published.calibration;
  const auto& c = r.calibration;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "real data (%.1f s): RMS camera %.3f projector %.3f stereo %.3f px\n"
      "  camera fx %+.2f %% fy %+.2f %% cx %+.1f cy %+.1f px; projector fx %+.2f %% fy %+.2f %% "
      "cx %+.1f cy %+.1f px\n"
      "  |dt| %.2f mm (t %.2f %.2f %.2f vs %.2f %.2f %.2f), rotation %.3f deg\n",
      seconds, r.report.camera_rms_px, r.report.projector_rms_px, r.report.stereo_rms_px,
      percent(c.camera.fx, ref.camera.fx), percent(c.camera.fy, ref.camera.fy),
      c.camera.cx - ref.camera.cx, c.camera.cy - ref.camera.cy,
      percent(c.projector.fx, ref.projector.fx), percent(c.projector.fy, ref.projector.fy),
      c.projector.cx - ref.projector.cx, c.projector.cy - ref.projector.cy, (c.t - ref.t).norm(),
      c.t.x(), c.t.y(), c.t.z(), ref.t.x(), ref.t.y(), ref.t.z(), degreesBetween(c.R, ref.R));
  for (const auto& p : r.report.poses)
    std::printf("  %s: %d corners, camera %.3f projector %.3f stereo %.3f px\n", p.label.c_str(),
                p.corners, p.camera_rms_px, p.projector_rms_px, p.stereo_rms_px);
  for (const auto& w : r.report.warnings) std::printf("  warning: %s\n", w.c_str());

  CHECK(r.report.camera_rms_px < 0.5);
  CHECK(r.report.projector_rms_px < 0.5);
  CHECK(r.report.stereo_rms_px < 0.5);
  CHECK(std::abs(percent(c.camera.fx, ref.camera.fx)) < 1.5);
  CHECK(std::abs(percent(c.camera.fy, ref.camera.fy)) < 1.5);
  CHECK(std::abs(percent(c.projector.fx, ref.projector.fx)) < 1.5);
  CHECK(std::abs(percent(c.projector.fy, ref.projector.fy)) < 1.5);
  CHECK(std::hypot(c.projector.cx - ref.projector.cx, c.projector.cy - ref.projector.cy) < 25.0);
  CHECK((c.t - ref.t).norm() < 3.0);

  // Self-consistency, independent of the published file: the corners
  // triangulated (camera ray x projector column, both lenses' distortion
  // applied) lie 10 mm apart. Measured 9.997..10.004 mm per pose; the
  // published calibration gives 9.945..10.037 mm on the same corners.
  for (const BoardView& v : views) {
    const double spacing = triangulatedSquareMm(c, v, board);
    INFO(v.label << ": triangulated square " << spacing << " mm");
    CHECK(std::abs(spacing - board.square_mm) < 0.02);
  }
}

namespace {

double radians(double degrees) { return degrees * std::numbers::pi / 180.0; }

// The simulated rig of config/sim.yaml, with a distorting camera lens.
sl::pipeline::CameraProjectorCalibration simulatedRig() { return sl::drivers::simRig(); }

struct BoardPose {
  double tilt_x_deg, tilt_y_deg, spin_deg;  // R = Rx * Ry * Rz of the board
  Eigen::Vector3d centre_mm;                // board centre, camera frame
};

// A plane carrying `board` centred at pose.centre_mm, facing the camera.
sl::drivers::SimPlane boardPlane(const Checkerboard& board, const BoardPose& pose) {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(radians(pose.tilt_x_deg), Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(radians(pose.tilt_y_deg), Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(radians(pose.spin_deg), Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  sl::drivers::SimCheckerboard texture;
  texture.cols = board.cols;
  texture.rows = board.rows;
  texture.square_mm = board.square_mm;
  texture.x_axis = R.col(0);
  texture.y_axis = R.col(1);
  texture.origin =
      pose.centre_mm - 0.5 * board.square_mm *
                           ((board.cols - 1) * texture.x_axis + (board.rows - 1) * texture.y_axis);
  texture.dark_albedo = 0.25;
  texture.light_albedo = 0.85;
  sl::drivers::SimPlane plane;
  plane.point = pose.centre_mm;
  plane.normal = -R.col(2);
  plane.albedo = 0.85;
  plane.checkerboard = texture;
  return plane;
}

}  // namespace

TEST_CASE("simulator round trip: calibration recovers the simulated rig", "[calibration][sim]") {
  const auto start = std::chrono::steady_clock::now();
  const Checkerboard board{13, 9, 15.0};
  PhaseShift33Pattern pattern;
  pattern.name = "3+3_both";
  pattern.direction = sl::pipeline::Direction::kBoth;
  const std::vector<BoardPose> poses = {
      {0, 0, 0, {0, 0, 560}},        {25, 0, 0, {0, 0, 560}},     {-25, 0, 5, {0, 0, 570}},
      {0, 25, 0, {10, 0, 550}},      {0, -25, -5, {-10, 0, 570}}, {18, 18, 10, {0, 10, 610}},
      {-18, 18, -10, {0, -10, 530}}, {18, -18, 0, {15, 0, 520}},  {-18, -18, 15, {-15, 0, 630}},
      {10, -10, 30, {0, 0, 660}},    {35, 10, 0, {0, 0, 600}},    {-35, -10, 0, {0, 0, 600}},
      {10, 35, 0, {0, 0, 600}},      {-10, -35, 0, {0, 0, 600}},
  };
  const sl::pipeline::CameraProjectorCalibration truth = simulatedRig();
  const PhaseShift33Decoder decoder(pattern, {});
  // The simulator has no optical blur: smooth its razor-sharp edges a little
  // before the sub-pixel refinement. Its squares span ~60 px: a wider window
  // averages more decoding noise into each local homography.
  sl::pipeline::CornerDetectionOptions corners;
  corners.presmooth_sigma_px = 1.0;
  sl::pipeline::LocalHomographyOptions homographies;
  homographies.window_radius_px = 25;
  std::vector<BoardView> views;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    sl::drivers::SimConfig config;
    config.rig = truth;
    config.patterns = {pattern};
    config.scene.planes = {boardPlane(board, poses[i])};
    const auto sensor = sl::drivers::SimulatedSensor::create(config);
    std::vector<cv::Mat> frames;
    for (int f = 0; f < pattern.frameCount(); ++f)
      frames.push_back(sensor->render(pattern.name, f, 1000 * i + f));
    const auto maps = decoder.decode(frames, 8);
    const auto result =
        sl::pipeline::observeBoard(sl::pipeline::meanImage(frames), maps, board,
                                   "pose" + std::to_string(i), corners, homographies);
    INFO(result.error);
    REQUIRE(result.view);
    // The observations themselves against the true projections.
    const sl::drivers::SimCheckerboard& texture = *config.scene.planes[0].checkerboard;
    const BoardView& view = *result.view;
    double camera_sum = 0, projector_sum = 0;
    for (std::size_t k = 0; k < view.corner_ids.size(); ++k) {
      const int id = view.corner_ids[k];
      const Eigen::Vector3d X =
          texture.origin + board.square_mm * ((id % board.cols) * texture.x_axis +
                                              (id / board.cols) * texture.y_axis);
      const Eigen::Vector2d qc = truth.camera.project(X);
      const Eigen::Vector2d qp = truth.projector.project(truth.R * X + truth.t);
      camera_sum += (Eigen::Vector2d(view.camera_px[k].x, view.camera_px[k].y) - qc).squaredNorm();
      projector_sum +=
          (Eigen::Vector2d(view.projector_px[k].x, view.projector_px[k].y) - qp).squaredNorm();
    }
    const double n = static_cast<double>(view.corner_ids.size());
    CHECK(view.corner_ids.size() >= 110);
    CHECK(std::sqrt(camera_sum / n) < 0.1);
    CHECK(std::sqrt(projector_sum / n) < 0.15);
    views.push_back(*result.view);
  }

  const CalibrationResult r = sl::pipeline::calibrateCameraProjector(
      views, board, cv::Size(1440, 1080), cv::Size(1824, 1140), CalibrationOptions{});
  const auto& c = r.calibration;
  const double baseline_error =
      (c.R.transpose() * c.t).norm() - (truth.R.transpose() * truth.t).norm();
  const double rotation_error = degreesBetween(c.R, truth.R);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "simulator (%.1f s, %zu poses): RMS camera %.3f projector %.3f stereo %.3f px\n"
      "  camera fx %+.3f %% fy %+.3f %% cx %+.2f cy %+.2f px; projector fx %+.3f %% fy %+.3f %% "
      "cx %+.2f cy %+.2f px\n"
      "  baseline %+.3f mm, |dt| %.3f mm, rotation %.4f deg\n",
      seconds, views.size(), r.report.camera_rms_px, r.report.projector_rms_px,
      r.report.stereo_rms_px, percent(c.camera.fx, truth.camera.fx),
      percent(c.camera.fy, truth.camera.fy), c.camera.cx - truth.camera.cx,
      c.camera.cy - truth.camera.cy, percent(c.projector.fx, truth.projector.fx),
      percent(c.projector.fy, truth.projector.fy), c.projector.cx - truth.projector.cx,
      c.projector.cy - truth.projector.cy, baseline_error, (c.t - truth.t).norm(), rotation_error);
  for (const auto& p : r.report.poses)
    std::printf("  %s: %d corners, camera %.3f projector %.3f stereo %.3f px\n", p.label.c_str(),
                p.corners, p.camera_rms_px, p.projector_rms_px, p.stereo_rms_px);

  CHECK(std::abs(percent(c.camera.fx, truth.camera.fx)) < 0.2);
  CHECK(std::abs(percent(c.camera.fy, truth.camera.fy)) < 0.2);
  CHECK(std::abs(percent(c.projector.fx, truth.projector.fx)) < 0.2);
  CHECK(std::abs(percent(c.projector.fy, truth.projector.fy)) < 0.2);
  CHECK(std::hypot(c.camera.cx - truth.camera.cx, c.camera.cy - truth.camera.cy) < 1.0);
  CHECK(std::hypot(c.projector.cx - truth.projector.cx, c.projector.cy - truth.projector.cy) < 1.0);
  CHECK(std::abs(baseline_error) < 0.1);
  CHECK(rotation_error < 0.02);
}

TEST_CASE("calibration files: OpenCV FileStorage export and sl_sensor import round trip",
          "[calibration][io]") {
  sl::files::CalibrationFile file;
  auto& c = file.calibration;
  c.camera = {1440, 1080, 2401.5, 2399.25, 719.75, 540.125, {-0.08, 0.12, 0.0005, -0.0003, 0.01}};
  c.projector = {1824, 1140, 2200.5, 2201.0, 911.0, 1130.5, {0.02, -0.01, 0, 0, 0}};
  c.R = Eigen::AngleAxisd(0.27, Eigen::Vector3d(0.1, 1, 0.05).normalized()).toRotationMatrix();
  c.t = Eigen::Vector3d(-144.7, 1.5, 39.5);
  file.errors = sl::files::CalibrationErrors{0.11, 0.22, 0.33};
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_calibration_io";
  fs::create_directories(dir);

  // Relative tolerance for intrinsics, absolute for distortion, R and t (mm).
  auto same = [](const sl::files::CalibrationFile& a, const sl::files::CalibrationFile& b,
                 double tolerance) {
    const auto& x = a.calibration;
    const auto& y = b.calibration;
    for (bool camera : {true, false}) {
      const auto& p = camera ? x.camera : x.projector;
      const auto& q = camera ? y.camera : y.projector;
      CHECK(p.width == q.width);
      CHECK(p.height == q.height);
      CHECK(p.fx == Approx(q.fx).epsilon(tolerance));
      CHECK(p.fy == Approx(q.fy).epsilon(tolerance));
      CHECK(p.cx == Approx(q.cx).epsilon(tolerance));
      CHECK(p.cy == Approx(q.cy).epsilon(tolerance));
      for (int i = 0; i < 5; ++i)
        CHECK(p.distortion[i] == Approx(q.distortion[i]).margin(tolerance));
    }
    CHECK((x.R - y.R).norm() < tolerance);
    CHECK((x.t - y.t).norm() < tolerance * 100);
  };

  SECTION("export as .xml and .yaml reads back through loadCalibration") {
    for (const char* name : {"exported.xml", "exported.yaml"}) {
      const std::string path = (dir / name).string();
      sl::files::exportOpenCvCalibration(file, path);
      const auto back = sl::files::loadCalibration(path);
      same(file, back, 1e-12);
      REQUIRE(back.errors);
      CHECK(back.errors->stereo_rms_px == Approx(0.33));
    }
  }

  SECTION("sl_sensor camera + projector files") {
    // Written the way sl_sensor's calibrator writes them (float matrices).
    const std::string camera = (dir / "primary_camera.xml").string();
    const std::string projector = (dir / "projector.xml").string();
    auto K = [](const sl::pipeline::PinholeModel& m) {
      return cv::Matx33f(float(m.fx), 0, float(m.cx), 0, float(m.fy), float(m.cy), 0, 0, 1);
    };
    auto d = [](const sl::pipeline::PinholeModel& m) {
      return cv::Vec<float, 5>(float(m.distortion[0]), float(m.distortion[1]),
                               float(m.distortion[2]), float(m.distortion[3]),
                               float(m.distortion[4]));
    };
    {
      cv::FileStorage out(camera, cv::FileStorage::WRITE);
      cv::Matx33f R;
      for (int i = 0; i < 9; ++i) R.val[i] = float(c.R(i / 3, i % 3));
      out << "intrinsic_mat" << cv::Mat(K(c.camera)) << "lens_distortion" << cv::Mat(d(c.camera))
          << "calibration_error" << 0.11 << "resolution_x" << c.camera.width << "resolution_y"
          << c.camera.height << "extrinsic_rot" << cv::Mat(R) << "extrinsic_trans"
          << cv::Mat(cv::Vec3f(float(c.t.x()), float(c.t.y()), float(c.t.z()))) << "stereo_error"
          << 0.33;
    }
    {
      cv::FileStorage out(projector, cv::FileStorage::WRITE);
      out << "intrinsic_mat" << cv::Mat(K(c.projector)) << "lens_distortion"
          << cv::Mat(d(c.projector)) << "calibration_error" << 0.22 << "resolution_x"
          << c.projector.width << "resolution_y" << c.projector.height;
    }
    const auto imported = sl::files::loadSlSensorCalibration(camera, projector);
    same(file, imported, 1e-6);
    REQUIRE(imported.errors);
    CHECK(imported.errors->projector_rms_px == Approx(0.22));
    // One file alone is refused with a pointer to the pair import.
    CHECK_THROWS_WITH(
        sl::files::loadCalibration(camera),
        Catch::Contains("sl_sensor camera file") && Catch::Contains("--import-sl-sensor"));
    CHECK_THROWS_WITH(sl::files::loadSlSensorCalibration(projector, camera),
                      Catch::Contains("swapped"));
  }
}

namespace {

struct ReferencePoint {
  int u, v;
  double x, y, z;
};

struct SkullComparison {
  std::size_t common = 0;                                   // pixels valid in both
  double median_dz = 0, median_abs_dz = 0, p95_abs_dz = 0;  // mm
  double within_1mm = 0;  // fraction of common pixels with |dz| <= 1 mm
};

// skull_2x3 decoded and triangulated as tests/process does (the data README's
// mask, images undistorted) with `calibration`, compared in z with SLStudio's
// reconstruction. projector_iterations: 0 ignores projector distortion.
SkullComparison compareSkull(const sl::pipeline::CameraProjectorCalibration& calibration,
                             int projector_iterations) {
  static const std::vector<ReferencePoint> reference = [] {
    std::vector<ReferencePoint> points;
    std::ifstream in(kSkull / "skull_gray" / "reference_points.txt");
    for (std::string line; std::getline(in, line);) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream s(line);
      ReferencePoint p{};
      s >> p.u >> p.v >> p.x >> p.y >> p.z;
      points.push_back(p);
    }
    return points;
  }();
  REQUIRE(!reference.empty());
  const auto pattern =
      sl::files::loadPattern(std::string(SL_SOURCE_DIR) + "/config/patterns/slstudio_2x3.yaml");
  const auto frames = sl::tools::loadFrames(sl::tools::listImages((kSkull / "skull_2x3").string()));
  sl::pipeline::DecoderOptions decoder;
  decoder.min_modulation = 55.0f / 3.0f;  // the data README's mask
  sl::pipeline::TriangulatorOptions triangulator;
  triangulator.projector_distortion_iterations = projector_iterations;
  const auto cloud =
      sl::tools::processCapture(pattern, calibration, frames, decoder, triangulator, true).cloud;
  std::vector<double> dz, adz;
  for (const ReferencePoint& p : reference) {
    const float z = cloud.points[static_cast<std::size_t>(p.v) * cloud.width + p.u].z;
    if (!std::isfinite(z)) continue;
    dz.push_back(z - p.z);
    adz.push_back(std::abs(z - p.z));
  }
  auto percentile = [](std::vector<double> v, double q) {
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, static_cast<std::size_t>(q * v.size()))];
  };
  SkullComparison r;
  r.common = dz.size();
  if (dz.empty()) return r;
  r.median_dz = percentile(dz, 0.5);
  r.median_abs_dz = percentile(adz, 0.5);
  r.p95_abs_dz = percentile(adz, 0.95);
  r.within_1mm =
      double(std::count_if(adz.begin(), adz.end(), [](double d) { return d <= 1.0; })) / adz.size();
  return r;
}

void printSkull(const std::string& what, const SkullComparison& s) {
  std::printf(
      "%s: %zu common pixels, median dz %+.3f mm, |dz| median %.3f p95 %.3f mm, "
      "%.2f %% within 1 mm\n",
      what.c_str(), s.common, s.median_dz, s.median_abs_dz, s.p95_abs_dz, 100 * s.within_1mm);
}

}  // namespace

// The codec engineer's real-data check (tests/process/test_process.cpp)
// repeated with this calibration instead of the published one. Hidden ([.]):
// it does NOT meet those thresholds, and no calibration from these five poses
// can be expected to. The reference points were triangulated with the
// published calibration, so the comparison measures how far two calibrations
// disagree in depth, not which one is right. Findings (issue 5):
// - Our observations agree with an SLStudio-style re-implementation
//   (modulation image, cornerSubPix 5 px, 21x21 window, LMEDS homography) to
//   0.02 px, and OpenCV with SLStudio's own flags (camera: principal point
//   fixed, fx = fy, k1; projector: fx = fy, k1) on them gives camera fx
//   +0.41 % off calibration.xml: the published file is not what these images
//   give (its projector RMS is 0.46 px, ours 0.31-0.35 px).
// - The published calibration predicts the projector corners from the
//   camera's board poses with 3.3 px RMS (5.0 px ignoring projector
//   distortion), ours with 0.77 px; ours triangulates the board squares at
//   10.000 mm (9.997..10.004 per pose), the published at 9.945..10.037.
// - Depth at the skull (z ~ 387 mm) follows the camera focal length, which five
//   poses fix to about +-1 %: leaving out one pose moves the median dz from
//   -0.3 mm (without seq1) to +5.3 mm (without seq4). A +-0.15 mm agreement
//   is far inside that spread.
// The projector's full model is used when triangulating (ignoring its ~4 px of
// modelled distortion would be inconsistent); with the five poses: median dz
// +1.30 mm, |dz| p95 2.26 mm, 28.6 % within 1 mm (+1.44 mm ignoring it).
// Run it explicitly: test_calibration "[skull]".
TEST_CASE("real captures: skull_2x3 triangulated with our calibration",
          "[.][calibration][real][skull]") {
  if (!fs::exists(kSkull / "skull_2x3")) {
    WARN("shared data not found at " << kSkull << ": skipped");
    return;
  }
  const Checkerboard board{13, 9, 10.0};
  std::vector<BoardView> views;
  for (const char* pose : {"seq1", "seq3", "seq4", "seq5", "seq6"})
    views.push_back(observeSlStudioPose(pose, board));
  CalibrationOptions options;
  options.camera.fix_principal_point = true;
  options.camera.fix_aspect_ratio = true;
  options.camera.radial_terms = 1;
  options.camera.tangential = false;
  const auto calibrate = [&](const std::vector<BoardView>& subset) {
    return sl::pipeline::calibrateCameraProjector(subset, board, cv::Size(1688, 1352),
                                                  cv::Size(1824, 1140), options)
        .calibration;
  };
  const int kProjectorIterations = 2;  // the projector model as calibrated
  // How much the answer depends on the choice of poses.
  for (std::size_t left_out = 0; left_out < views.size(); ++left_out) {
    std::vector<BoardView> subset = views;
    subset.erase(subset.begin() + static_cast<std::ptrdiff_t>(left_out));
    printSkull("  without " + views[left_out].label,
               compareSkull(calibrate(subset), kProjectorIterations));
  }
  const SkullComparison s = compareSkull(calibrate(views), kProjectorIterations);
  printSkull("skull_2x3 with our calibration", s);
  CHECK(s.common >= 75000);
  CHECK(std::abs(s.median_dz) <= 0.15);
  CHECK(s.median_abs_dz < 0.2);
  CHECK(s.p95_abs_dz < 0.8);
  CHECK(s.within_1mm >= 0.97);
}

namespace {

// Corner observations of `board` in `pose` projected through the rig, with
// Gaussian noise of sigma_camera / sigma_projector px (the corner noise the
// simulator's full render -> decode -> detect chain shows, see the round
// trip above: ~0.1 px).
BoardView syntheticView(const sl::pipeline::CameraProjectorCalibration& rig,
                        const Checkerboard& board, const BoardPose& pose, double sigma_camera,
                        double sigma_projector, cv::RNG& rng, const std::string& label) {
  const sl::drivers::SimCheckerboard texture = *boardPlane(board, pose).checkerboard;
  BoardView v;
  v.label = label;
  for (int id = 0; id < board.cornerCount(); ++id) {
    const Eigen::Vector3d X = texture.origin + board.square_mm * ((id % board.cols) * texture.x_axis +
                                                                  (id / board.cols) * texture.y_axis);
    const Eigen::Vector2d qc = rig.camera.project(X);
    const Eigen::Vector2d qp = rig.projector.project(rig.R * X + rig.t);
    v.corner_ids.push_back(id);
    v.camera_px.emplace_back(qc.x() + rng.gaussian(sigma_camera), qc.y() + rng.gaussian(sigma_camera));
    v.projector_px.emplace_back(qp.x() + rng.gaussian(sigma_projector),
                                qp.y() + rng.gaussian(sigma_projector));
  }
  return v;
}

struct Spread {
  std::vector<double> values, sigmas;
  void add(double value, double sigma) {
    values.push_back(value);
    sigmas.push_back(sigma);
  }
  double std() const {
    double m = 0, s = 0;
    for (double v : values) m += v;
    m /= values.size();
    for (double v : values) s += (v - m) * (v - m);
    return std::sqrt(s / (values.size() - 1));
  }
  double meanSigma() const {
    double m = 0;
    for (double v : sigmas) m += v;
    return m / sigmas.size();
  }
};

}  // namespace

TEST_CASE("reported 1-sigma uncertainties agree with the spread over noise seeds",
          "[calibration][uncertainty]") {
  const auto rig = simulatedRig();
  const Checkerboard board{13, 9, 15.0};
  const std::vector<BoardPose> poses = {
      {0, 0, 0, {0, 0, 560}},    {25, 0, 0, {0, 0, 560}},     {-25, 0, 5, {0, 0, 570}},
      {0, 25, 0, {10, 0, 550}},  {0, -25, -5, {-10, 0, 570}}, {18, 18, 10, {0, 10, 610}},
      {-18, 18, -10, {0, -10, 530}}, {18, -18, 0, {15, 0, 520}}};
  std::map<std::string, Spread> spread;
  constexpr int kSeeds = 24;
  for (int seed = 0; seed < kSeeds; ++seed) {
    cv::RNG rng(1000 + seed);
    std::vector<BoardView> views;
    for (std::size_t i = 0; i < poses.size(); ++i)
      views.push_back(syntheticView(rig, board, poses[i], 0.1, 0.15, rng, "pose" + std::to_string(i)));
    const CalibrationResult r = sl::pipeline::calibrateCameraProjector(
        views, board, cv::Size(1440, 1080), cv::Size(1824, 1140), CalibrationOptions{});
    const auto& c = r.calibration;
    const auto& u = r.report.uncertainty;
    spread["camera fx"].add(c.camera.fx, u.camera.fx);
    spread["camera fy"].add(c.camera.fy, u.camera.fy);
    spread["camera cx"].add(c.camera.cx, u.camera.cx);
    spread["camera cy"].add(c.camera.cy, u.camera.cy);
    spread["camera k1"].add(c.camera.distortion[0], u.camera.distortion[0]);
    spread["projector fx"].add(c.projector.fx, u.projector.fx);
    spread["projector fy"].add(c.projector.fy, u.projector.fy);
    spread["projector cx"].add(c.projector.cx, u.projector.cx);
    spread["projector cy"].add(c.projector.cy, u.projector.cy);
    spread["projector k1"].add(c.projector.distortion[0], u.projector.distortion[0]);
    const Eigen::AngleAxisd d(c.R * rig.R.transpose());
    const Eigen::Vector3d rotation = d.angle() * d.axis() * 180.0 / std::numbers::pi;
    for (int q = 0; q < 3; ++q) {
      spread["rotation " + std::to_string(q)].add(rotation(q), u.rotation_deg(q));
      spread["translation " + std::to_string(q)].add(c.t(q), u.translation_mm(q));
    }
  }
  for (const auto& [name, s] : spread) {
    const double ratio = s.meanSigma() / s.std();
    std::printf("uncertainty %-14s reported %.3g, spread over %d seeds %.3g (ratio %.2f)\n",
                name.c_str(), s.meanSigma(), kSeeds, s.std(), ratio);
    CAPTURE(name, s.meanSigma(), s.std());
    CHECK(ratio > 0.5);
    CHECK(ratio < 2.0);
  }
}

TEST_CASE("poorly constrained calibrations warn and suggest poses", "[calibration][uncertainty]") {
  const auto rig = simulatedRig();
  const Checkerboard board{13, 9, 15.0};
  // Five poses, all nearly facing the camera at one distance, in the middle
  // of the image, with real-capture noise: the projector is poorly pinned.
  const std::vector<BoardPose> few = {{0, 0, 0, {0, 0, 600}},
                                      {5, 0, 0, {0, 0, 600}},
                                      {0, 5, 0, {0, 0, 605}},
                                      {-5, 0, 3, {0, 0, 600}},
                                      {0, -5, 0, {0, 0, 598}}};
  cv::RNG rng(7);
  std::vector<BoardView> views;
  for (std::size_t i = 0; i < few.size(); ++i)
    views.push_back(syntheticView(rig, board, few[i], 0.3, 0.3, rng, "pose" + std::to_string(i)));
  const CalibrationResult r = sl::pipeline::calibrateCameraProjector(
      views, board, cv::Size(1440, 1080), cv::Size(1824, 1140), CalibrationOptions{});
  std::string warnings, advice;
  for (const auto& w : r.report.warnings) warnings += w + "\n";
  for (const auto& a : r.report.advice) advice += a + "\n";
  INFO(warnings << advice);
  CHECK(warnings.find("projector fx uncertain") != std::string::npos);
  CHECK(advice.find("tilt the board more") != std::string::npos);
  CHECK(advice.find("vary the distance") != std::string::npos);
  CHECK(advice.find("cover the projector's image") != std::string::npos);
  // The well-spread set of the round trip does not warn.
  const std::vector<BoardPose> good = {
      {0, 0, 0, {0, 0, 560}},    {35, 0, 0, {0, 0, 560}},      {-35, 0, 5, {0, 0, 570}},
      {0, 35, 0, {10, 0, 550}},  {0, -35, -5, {-10, 0, 570}},  {18, 18, 10, {60, 40, 610}},
      {-18, 18, -10, {-60, -40, 480}}, {18, -18, 0, {60, -40, 520}}, {-18, -18, 15, {-60, 40, 680}}};
  std::vector<BoardView> good_views;
  for (std::size_t i = 0; i < good.size(); ++i)
    good_views.push_back(syntheticView(rig, board, good[i], 0.1, 0.15, rng, "g" + std::to_string(i)));
  const CalibrationResult ok = sl::pipeline::calibrateCameraProjector(
      good_views, board, cv::Size(1440, 1080), cv::Size(1824, 1140), CalibrationOptions{});
  std::string ok_warnings;
  for (const auto& w : ok.report.warnings) ok_warnings += w + "\n";
  INFO(ok_warnings);
  CHECK(ok.report.advice.empty());
}

namespace {

struct CliRun {
  int exit_code;
  std::string output;  // stdout and stderr
};

CliRun runCli(const std::string& args, const fs::path& log) {
  const std::string command =
      std::string(SL_BINARY_DIR) + "/tools/" + args + " > " + log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream in(log);
  std::stringstream text;
  text << in.rdbuf();
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text.str()};
}

// Five board poses on the simulator as pose folders of PNG frames (3+3_both,
// sl_calibrate's built-in pattern), with the projector `brightness_dn` bright.
// With `moved_mm`, the board of each pose is that much nearer the camera
// (farther for odd poses) in the column frames (0-5) than in the row frames
// (6-11): a board knocked during the sequence. The shading image blends the
// two, nearly alike; the projector columns disagree with the corners.
std::vector<std::string> writeSimulatedPoses(const fs::path& dir, double brightness_dn,
                                             double moved_mm = 0) {
  const Checkerboard board{13, 9, 15.0};
  PhaseShift33Pattern pattern;
  pattern.name = "3+3_both";
  pattern.direction = sl::pipeline::Direction::kBoth;
  const std::vector<BoardPose> poses = {{0, 0, 0, {0, 0, 560}},
                                        {25, 0, 0, {0, 0, 560}},
                                        {0, 25, 0, {10, 0, 550}},
                                        {18, -18, 0, {15, 0, 520}},
                                        {-18, -18, 15, {-15, 0, 630}}};
  std::vector<std::string> folders;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    sl::drivers::SimConfig config;
    config.rig = simulatedRig();
    config.patterns = {pattern};
    config.scene.planes = {boardPlane(board, poses[i])};
    config.projector_brightness_dn = brightness_dn;
    const auto sensor = sl::drivers::SimulatedSensor::create(config);
    BoardPose moved = poses[i];
    moved.centre_mm.z() += (i % 2 ? moved_mm : -moved_mm);
    config.scene.planes = {boardPlane(board, moved)};
    const auto moved_sensor = sl::drivers::SimulatedSensor::create(config);
    const fs::path folder = dir / ("pose" + std::to_string(i));
    fs::create_directories(folder);
    for (int f = 0; f < pattern.frameCount(); ++f) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%02d.png", f);
      const auto& source = f < pattern.frameCount() / 2 ? moved_sensor : sensor;
      REQUIRE(cv::imwrite((folder / name).string(), source->render(pattern.name, f, 1000 * i + f)));
    }
    folders.push_back(folder.string());
  }
  return folders;
}

}  // namespace

TEST_CASE("sl_calibrate: saturated poses say so with numbers, --keep-saturated, RMS limit",
          "[calibration][sim][cli]") {
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_calibration_cli";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path log = dir / "log.txt";
  auto poses = [](const std::vector<std::string>& folders) {
    std::string list;
    for (const std::string& f : folders) list += " " + f;
    return list;
  };
  const std::string board = " --board 13x9 --square 15 --presmooth 1 --window-radius 25";

  auto count = [](const std::string& text, const std::string& what) {
    int n = 0;
    for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
  };
  SECTION("an overexposed capture: poses skipped naming saturation, kept with the flag") {
    // 9 x the default brightness: light and dark squares both clip in the
    // bright frames of every sequence.
    const auto folders = writeSimulatedPoses(dir / "bright", 2000.0);
    const CliRun r = runCli("sl_calibrate --poses" + poses(folders) + board + " --out " +
                                (dir / "bright.yaml").string(),
                            log);
    INFO(r.output);
    const int skipped = count(r.output, "sl_calibrate: skipping");
    CHECK(skipped >= 3);
    CHECK(r.exit_code == 1);  // fewer than 3 usable poses
    CHECK(count(r.output, "% saturated") >= skipped);
    // The corners, counted: found in the shading image, with a projector coordinate.
    CHECK(count(r.output, "corners found in the shading image: 117 of 117; pixels: ") >= skipped);
    CHECK(count(r.output, " of 117 corners have a projector coordinate") >= skipped);
    CHECK(r.output.find("% decoded") != std::string::npos);
    CHECK(r.output.find("--keep-saturated") != std::string::npos);
    const CliRun kept = runCli("sl_calibrate --poses" + poses(folders) + board +
                                   " --keep-saturated --accept --out " +
                                   (dir / "bright_kept.yaml").string(),
                               log);
    INFO(kept.output);
    CHECK(kept.exit_code == 0);
    CHECK(count(kept.output, "sl_calibrate: skipping") < skipped);
    CHECK(fs::exists(dir / "bright_kept.yaml"));
  }
  SECTION("a result beyond --max-rms exits 3 after the report, without the calibration file") {
    const auto folders = writeSimulatedPoses(dir / "normal", 220.0);
    const CliRun ok = runCli(
        "sl_calibrate --poses" + poses(folders) + board + " --out " + (dir / "ok.yaml").string(),
        log);
    INFO(ok.output);
    CHECK(ok.exit_code == 0);
    CHECK(fs::exists(dir / "ok.yaml"));
    // The same poses against a limit below their RMS (about 0.05 px).
    const CliRun beyond = runCli("sl_calibrate --poses" + poses(folders) + board +
                                     " --max-rms 0.001 --out " + (dir / "beyond.yaml").string(),
                                 log);
    INFO(beyond.output);
    CHECK(beyond.exit_code == 3);
    CHECK(beyond.output.find("RMS reprojection error: camera") != std::string::npos);
    CHECK(beyond.output.find("beyond --max-rms") != std::string::npos);
    CHECK_FALSE(fs::exists(dir / "beyond.yaml"));
    const CliRun accepted = runCli("sl_calibrate --poses" + poses(folders) + board +
                                       " --max-rms 0.001 --accept --out " +
                                       (dir / "accepted.yaml").string(),
                                   log);
    INFO(accepted.output);
    CHECK(accepted.exit_code == 0);
    CHECK(fs::exists(dir / "accepted.yaml"));
  }
  SECTION("a board knocked during every sequence: beyond the default 2 px, exit 3") {
    const auto folders = writeSimulatedPoses(dir / "moved", 220.0, 15.0);
    const CliRun r = runCli("sl_calibrate --poses" + poses(folders) + board + " --out " +
                                (dir / "moved.yaml").string(),
                            log);
    INFO(r.output);
    CHECK(r.exit_code == 3);
    CHECK(r.output.find("RMS reprojection error: camera") != std::string::npos);
    CHECK(r.output.find("per pose (RMS px):") != std::string::npos);
    CHECK(r.output.find("beyond --max-rms 2 px") != std::string::npos);
    CHECK_FALSE(fs::exists(dir / "moved.yaml"));
  }
}

// Every option a tool's parser compares against (a "--name" literal of its
// source; sl_calibrate's --camera-/--projector- flags are composed, so they
// are listed here) has a line of its own in --help, and --help exits 0.
TEST_CASE("sl_process, sl_calibrate and sl_patterns --help list every option, exit 0", "[cli]") {
  const fs::path log = fs::path(SL_BINARY_DIR) / "test_calibration_help.txt";
  const std::regex literal("\"(--[a-z0-9]+(-[a-z0-9]+)*)\"");
  for (const auto& [tool, source] :
       std::vector<std::pair<std::string, std::string>>{
           {"sl_process", "tools/sl_process/main.cpp"},
           {"sl_calibrate", "tools/sl_calibrate/sl_calibrate.cpp"},
           {"sl_patterns", "tools/sl_patterns/main.cpp"}}) {
    std::ifstream in(fs::path(SL_SOURCE_DIR) / source);
    REQUIRE(in);
    std::stringstream text;
    text << in.rdbuf();
    const std::string code = text.str();
    std::set<std::string> options;
    for (auto it = std::sregex_iterator(code.begin(), code.end(), literal);
         it != std::sregex_iterator(); ++it)
      options.insert((*it)[1].str());
    if (tool == "sl_calibrate")
      for (const char* device : {"camera", "projector"})
        for (const char* flag : {"fix-principal-point", "fix-aspect-ratio", "no-tangential",
                                 "radial-terms"})
          options.insert(std::string("--") + device + "-" + flag);
    INFO(tool << ": " << options.size() << " options");
    CHECK(options.size() >= 5);
    CHECK(options.count("--help") == 1);
    const CliRun help = runCli(tool + " --help", log);
    CHECK(help.exit_code == 0);
    CHECK(help.output.rfind("usage: " + tool, 0) == 0);
    CHECK(help.output.find(tool + ": help") == std::string::npos);
    // The lines that introduce an option: "  --name ..." or "  -h, --help ...".
    std::vector<std::string> lines;
    std::stringstream output(help.output);
    for (std::string line; std::getline(output, line);) lines.push_back(line + " ");
    for (const std::string& option : options) {
      INFO(tool << " " << option << "\n" << help.output);
      int introduced = 0;
      for (const std::string& line : lines) {
        const auto first = line.find_first_not_of(' ');
        if (first == 0 || first == std::string::npos) continue;  // not indented: no option line
        const std::string start = line.substr(first);
        if (start.rfind(option + " ", 0) == 0 || start.rfind("-h, " + option + " ", 0) == 0)
          ++introduced;
      }
      CHECK(introduced == 1);
    }
  }
}
