// Tests of the simulator's moving sensor, solid primitives (cone, box,
// height field, shadows) and second camera. Bounded: no live run waits longer
// than a few hundred milliseconds.
#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>

#include "sl/drivers/sim.h"
#include "support/sim_rig.h"
#include "support/time_scale.h"

namespace {

using namespace std::chrono_literals;
using sl::drivers::SimBox;
using sl::drivers::SimCone;
using sl::drivers::SimConfig;
using sl::drivers::SimHeightField;
using sl::drivers::SimPlane;
using sl::drivers::SimRoughness;
using sl::drivers::SimSphere;
using sl::drivers::SimulatedSensor;

double degrees(double d) { return d * std::numbers::pi / 180.0; }

using sl::test::simDefaultRig;

SimConfig baseConfig() { return sl::test::simConfig33("3+3_horizontal"); }

Eigen::Vector3d at(const cv::Mat& xyz, int row, int col) {
  const cv::Vec3f p = xyz.at<cv::Vec3f>(row, col);
  return {p[0], p[1], p[2]};
}

}  // namespace

TEST_CASE("moving sensor: each image sees the scene through the inverse motion",
          "[sim][motion]") {
  SimConfig c = baseConfig();
  c.scene.planes = {SimPlane{{0, 0, 600}, {0, 0, -1}, 0.8}};
  c.scene.spheres = {SimSphere{{20, 0, 540}, 50, 0.7}};
  c.motion.velocity_mm_s = {60, 0, 0};  // 2 mm per image at 30 fps
  c.gain_dn_per_electron = 0;
  c.read_noise_dn = 0;
  const auto sensor = SimulatedSensor::create(c);

  // Ground truth of image 3: the sensor moved 6 mm along +x.
  const sl::drivers::SimGroundTruth gt3 = sensor->groundTruthAt(0, 3);
  double max_error = 0;
  int sphere_pixels = 0;
  for (int r = 0; r < 1080; r += 7)
    for (int col = 0; col < 1440; col += 7) {
      const Eigen::Vector3d x = at(gt3.xyz_mm, r, col) + Eigen::Vector3d(6, 0, 0);  // image-0 frame
      const double to_sphere = std::abs((x - Eigen::Vector3d(20, 0, 540)).norm() - 50);
      const double to_plane = std::abs(x.z() - 600);
      if (to_sphere < to_plane) ++sphere_pixels;
      max_error = std::max(max_error, std::min(to_sphere, to_plane));
    }
  CHECK(max_error < 1e-3);
  CHECK(sphere_pixels > 100);
  // Image 0 is the configured pose.
  CHECK(cv::norm(sensor->groundTruthAt(0, 0).depth_mm, sensor->groundTruth().depth_mm,
                 cv::NORM_INF) == 0);

  // Equivalent static scene: everything moved by -6 mm.
  SimConfig shifted = c;
  shifted.motion = {};
  shifted.scene.planes[0].point.x() -= 6;
  shifted.scene.spheres[0].center.x() -= 6;
  const auto still = SimulatedSensor::create(shifted);
  const cv::Mat moving_image = sensor->render("3+3_horizontal", 3, 5);
  const cv::Mat still_image = still->render("3+3_horizontal", 3, 5);
  cv::Mat diff;
  cv::absdiff(moving_image, still_image, diff);
  CHECK(cv::norm(diff, cv::NORM_INF) <= 1);
  CHECK(cv::mean(diff)[0] < 0.01);

  // Cost of one moving image (ray casting + rendering), reported.
  const auto t0 = std::chrono::steady_clock::now();
  constexpr int kImages = 6;
  for (int i = 0; i < kImages; ++i) (void)sensor->render("3+3_horizontal", i, 7);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() /
      kImages;
  const auto t1 = std::chrono::steady_clock::now();
  for (int i = 0; i < kImages; ++i) (void)still->render("3+3_horizontal", i, 7);
  const double static_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count() /
      kImages;
  WARN("render per 1440x1080 image (plane + sphere): moving sensor " << ms << " ms, static "
                                                                     << static_ms << " ms");
  CHECK(ms < 500 * sl::test::kTimeScale);
}

TEST_CASE("moving sensor: per-image poses", "[sim][motion]") {
  SimConfig c = baseConfig();
  c.scene.planes = {SimPlane{{0, 0, 600}, {0, 0, -1}, 0.8}};
  Eigen::Isometry3d forward = Eigen::Isometry3d::Identity();
  forward.translation() = Eigen::Vector3d(0, 0, 10);
  c.motion.poses = {Eigen::Isometry3d::Identity(), forward};
  const auto sensor = SimulatedSensor::create(c);
  CHECK(std::abs(sensor->groundTruthAt(0, 1).depth_mm.at<float>(540, 720) - 590.0f) < 1e-3);
  CHECK(std::abs(sensor->groundTruthAt(0, 2).depth_mm.at<float>(540, 720) - 600.0f) < 1e-3);
}

TEST_CASE("cone, box and height field match the analytic surfaces", "[sim][geometry]") {
  SimConfig c = baseConfig();
  c.scene.planes = {SimPlane{{0, 0, 600}, {0, 0, -1}, 0.8}};
  // Cone standing on the plane towards the camera, apex on the optical axis.
  c.scene.cones = {SimCone{{0, 0, 600}, {0, 0, -1}, 10, 60, 0.8}};
  // Box with its front face at z = 520.
  c.scene.boxes = {SimBox{{-80, 40, 540}, {30, 30, 40}, Eigen::Matrix3d::Identity(), 0.8}};
  // Height field: a ramp rising 0.1 mm per mm along x.
  SimHeightField field;
  field.origin = {80, -50, 590};
  field.width_mm = 40;
  field.length_mm = 40;
  field.cell_mm = 1;
  field.heights_mm = cv::Mat(41, 41, CV_32FC1);
  for (int r = 0; r < 41; ++r)
    for (int col = 0; col < 41; ++col) field.heights_mm.at<float>(r, col) = 0.1f * col;
  c.scene.height_fields = {field};
  const auto sensor = SimulatedSensor::create(c);
  const sl::drivers::SimGroundTruth& gt = sensor->groundTruth();
  const auto& camera = c.rig.camera;
  auto pixel = [&](const Eigen::Vector3d& x) {
    const Eigen::Vector2d p = camera.project(x);
    return cv::Point(int(std::lround(p.x())), int(std::lround(p.y())));
  };
  // Apex at z = 540: the nearest point (steep flank: 1.35 mm of depth per pixel).
  const cv::Point apex = pixel({0, 0, 540});
  double nearest = 1e9;
  for (int dr = -2; dr <= 2; ++dr)
    for (int dc = -2; dc <= 2; ++dc)
      nearest = std::min(nearest, double(gt.depth_mm.at<float>(apex.y + dr, apex.x + dc)));
  CHECK(std::abs(nearest - 540.0) < 1.4);
  // Points on the cone's flank satisfy the cone equation.
  const double tan_half = 10.0 / 60.0;
  for (double r_mm : {2.0, 5.0, 8.0}) {
    const cv::Point p = pixel({r_mm, 0, 540 + r_mm / tan_half});
    const Eigen::Vector3d x = at(gt.xyz_mm, p.y, p.x);
    const double radius = std::hypot(x.x(), x.y());
    CHECK(std::abs(radius - (x.z() - 540) * tan_half) < 1e-3);
  }
  // Box front face.
  CHECK(std::abs(gt.depth_mm.at<float>(pixel({-80, 40, 520})) - 520.0f) < 1e-3f);
  // Height field: z = 590 - 0.1 * (x - 60) over x in [60, 100].
  for (double x_mm : {65.0, 80.0, 95.0}) {
    const cv::Point p = pixel({x_mm, -50, 590});
    const Eigen::Vector3d x = at(gt.xyz_mm, p.y, p.x);
    CHECK(std::abs(x.z() - (590 - 0.1 * (x.x() - 60))) < 2e-3);
  }
  // Shadows: the projector (150 mm to the right) leaves plane points left of
  // the cone's base (apex shadow at x = -16.7) and of the box unlit, and
  // lights those right of them.
  CHECK(gt.lit.at<std::uint8_t>(pixel({-13, 0, 600})) == 0);
  CHECK(gt.lit.at<std::uint8_t>(pixel({-20, 0, 600})) == 255);
  CHECK(gt.lit.at<std::uint8_t>(pixel({13, 0, 600})) == 255);
  CHECK(gt.lit.at<std::uint8_t>(pixel({-120, 40, 600})) == 0);
  CHECK(gt.lit.at<std::uint8_t>(pixel({-60, 40, 600})) == 255);
}

TEST_CASE("rough height field: target RMS, deterministic in the seed", "[sim][geometry]") {
  SimConfig c = baseConfig();
  SimHeightField field;
  field.origin = {0, 0, 500};
  field.width_mm = 100;
  field.length_mm = 80;
  field.cell_mm = 0.5;
  field.roughness = SimRoughness{0.2, 4.0, 0.8, 42};
  c.scene.height_fields = {field};
  const auto a = SimulatedSensor::create(c);
  const auto b = SimulatedSensor::create(c);
  const cv::Mat& h = a->config().scene.height_fields[0].heights_mm;
  REQUIRE(h.size() == cv::Size(201, 161));
  cv::Scalar mean, stddev;
  cv::meanStdDev(h, mean, stddev);
  CHECK(std::abs(stddev[0] - 0.2) < 1e-4);
  CHECK(cv::norm(h, b->config().scene.height_fields[0].heights_mm, cv::NORM_INF) == 0);
  c.scene.height_fields[0].roughness->seed = 43;
  const auto other = SimulatedSensor::create(c);
  CHECK(cv::norm(h, other->config().scene.height_fields[0].heights_mm, cv::NORM_INF) > 0.1);
  // The camera sees the surface within the rms band around z = 500.
  const cv::Mat& depth = a->groundTruth().depth_mm;
  const float z = depth.at<float>(540, 720);
  CHECK(std::abs(z - 500.0f) < 1.5f);
}

TEST_CASE("second camera: own rig, same projector schedule", "[sim][camera]") {
  SimConfig c = baseConfig();
  c.scene.planes = {SimPlane{{0, 0, 600}, {0, 0, -1}, 0.8}};
  // "left" camera 100 mm left of the first (the projector 250 mm to its right).
  sl::drivers::SimCamera left;
  left.rig = simDefaultRig();
  // Camera-1 frame in the first camera's frame: 100 mm to the left, turned 8 deg right.
  const Eigen::Matrix3d R_first_left =
      Eigen::AngleAxisd(degrees(8), Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Vector3d t_first_left(-100, 0, 0);
  // X_p = R0 X_0 + t0 = R0 (R_fl X_l + t_fl) + t0.
  left.rig.R = c.rig.R * R_first_left;
  left.rig.t = c.rig.R * t_first_left + c.rig.t;
  c.second_camera = left;
  const auto sensor = SimulatedSensor::create(c);
  const auto cameras = sensor->cameras();
  REQUIRE(cameras.size() == 2);
  CHECK(cameras[0] == sensor->camera());
  CHECK(cameras[1]->id() == "sim_left");
  // Points seen by the left camera lie on the plane z = 600 of the first camera.
  const sl::drivers::SimGroundTruth gt = sensor->groundTruthAt(1, 0);
  double max_error = 0;
  for (int r = 0; r < 1080; r += 13)
    for (int col = 0; col < 1440; col += 13) {
      const Eigen::Vector3d x = R_first_left * at(gt.xyz_mm, r, col) + t_first_left;
      max_error = std::max(max_error, std::abs(x.z() - 600));
    }
  CHECK(max_error < 1e-3);
  CHECK(cv::countNonZero(gt.lit) > 0.5 * 1440 * 1080);
  CHECK(cv::norm(sensor->render(1, "3+3_horizontal", 0, 1), sensor->render(0, "3+3_horizontal", 0, 1),
                 cv::NORM_L1) > 0);
  CHECK_THROWS_AS(sensor->render(2, "3+3_horizontal", 0, 1), std::out_of_range);

  // Live: both cameras receive the frames of one sequence.
  for (const auto& camera : cameras) camera->start();
  sensor->projector()->start(1);
  for (const auto& camera : cameras) {
    int frames = 0;
    std::uint64_t first_stamp = 0;
    while (auto f = camera->grab(400ms)) {
      if (frames == 0) first_stamp = f->stamp_ns;
      CHECK(f->image.size() == cv::Size(1440, 1080));
      ++frames;
    }
    CHECK(frames == 6);
    CHECK(first_stamp > 0);
  }
  for (const auto& camera : cameras) camera->stop();
}
