// Tests of the simulated sensor: ground-truth geometry, shadows, radiometry
// and noise, determinism, and the real-time trigger schedule. Every wait is
// bounded by a timeout, so a broken schedule fails instead of hanging.
#include <Eigen/Geometry>
#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <future>
#include <numbers>
#include <opencv2/core.hpp>
#include <thread>
#include <vector>

#include "sl/drivers/sim.h"
#include "support/time_scale.h"

namespace {

using namespace std::chrono_literals;
using sl::drivers::SimConfig;
using sl::drivers::SimPlane;
using sl::drivers::SimSphere;
using sl::drivers::SimulatedSensor;
using sl::pipeline::PhaseShift33Pattern;

double degrees(double d) { return d * std::numbers::pi / 180.0; }

// A plausible rig: 1440x1080 camera with a mildly distorting lens; a
// LightCrafter 4500 addressed as 1824x1140 with the usual 100 % vertical
// offset (cy at the bottom row), mounted 160 mm to the right of the camera,
// yawed 15 deg towards it (optical axes cross at ~600 mm) and pitched 14.5
// deg so its offset image is centred on the camera's view.
sl::pipeline::CameraProjectorCalibration realisticRig() {
  sl::pipeline::CameraProjectorCalibration rig;
  rig.camera.width = 1440;
  rig.camera.height = 1080;
  rig.camera.fx = 2400;
  rig.camera.fy = 2400;
  rig.camera.cx = 719.5;
  rig.camera.cy = 539.5;
  rig.camera.distortion = {-0.08, 0.12, 0.0005, -0.0003, 0};
  rig.projector.width = 1824;
  rig.projector.height = 1140;
  rig.projector.fx = 2200;
  rig.projector.fy = 2200;
  rig.projector.cx = 911.5;
  rig.projector.cy = 1139;
  rig.projector.distortion = {0.02, -0.01, 0, 0, 0};
  rig.R = (Eigen::AngleAxisd(degrees(14.5), Eigen::Vector3d::UnitX()) *
           Eigen::AngleAxisd(degrees(15), Eigen::Vector3d::UnitY()))
              .toRotationMatrix();
  const Eigen::Vector3d projector_center{160, 0, 0};  // camera frame, mm
  rig.t = -rig.R * projector_center;
  return rig;
}

PhaseShift33Pattern pattern(const std::string& name, sl::pipeline::Direction direction) {
  PhaseShift33Pattern p;
  p.name = name;
  p.direction = direction;
  return p;
}

SimConfig realisticConfig() {
  SimConfig c;
  c.rig = realisticRig();
  c.patterns = {pattern("3+3_horizontal", sl::pipeline::Direction::kHorizontal),
                pattern("3+3_vertical", sl::pipeline::Direction::kVertical)};
  return c;
}

SimConfig planeAt(double z_mm) {
  SimConfig c = realisticConfig();
  c.scene.planes = {SimPlane{{0, 0, z_mm}, {0, 0, -1}, 0.8}};
  return c;
}

Eigen::Vector3d projectorCenter(const SimConfig& c) { return -c.rig.R.transpose() * c.rig.t; }

Eigen::Vector3d gtPoint(const SimulatedSensor& s, int row, int col) {
  const cv::Vec3f p = s.groundTruth().xyz_mm.at<cv::Vec3f>(row, col);
  return {p[0], p[1], p[2]};
}

Eigen::Vector3d cameraRay(const SimConfig& c, int row, int col) {
  const Eigen::Vector2d xn = c.rig.camera.pixelToNormalized({double(col), double(row)});
  return {xn.x(), xn.y(), 1.0};
}

double litFraction(const SimulatedSensor& s) {
  return double(cv::countNonZero(s.groundTruth().lit)) / double(s.groundTruth().lit.total());
}

// Bilinear sample of an 8-bit projector image at (u, v), pixel centres at integers.
double sampleBilinear(const cv::Mat& image, double u, double v) {
  u = std::clamp(u, 0.0, image.cols - 1.0);
  v = std::clamp(v, 0.0, image.rows - 1.0);
  const int x0 = std::min(int(u), image.cols - 2), y0 = std::min(int(v), image.rows - 2);
  const double fx = u - x0, fy = v - y0;
  auto at = [&](int y, int x) { return double(image.at<std::uint8_t>(y, x)); };
  return (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) +
         fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1));
}

// The expected noise-free signal (8-bit DN) of a lit pixel on a plane with
// unit normal `normal`, computed from the ground truth and the config.
double modelSignal(const SimulatedSensor& s, const cv::Mat& projector_image,
                   const Eigen::Vector3d& normal, double albedo, int row, int col) {
  const SimConfig& c = s.config();
  const Eigen::Vector3d x = gtPoint(s, row, col);
  const Eigen::Vector3d to_projector = projectorCenter(c) - x;
  const double cos_incidence = std::abs(normal.dot(to_projector.normalized()));
  const double falloff = c.reference_distance_mm / to_projector.norm();
  const double level = sampleBilinear(projector_image, s.groundTruth().up.at<float>(row, col),
                                      s.groundTruth().vp.at<float>(row, col));
  return c.ambient_dn * albedo +
         c.projector_brightness_dn * albedo * cos_incidence * falloff * falloff * level / 255.0;
}

}  // namespace

TEST_CASE("fronto-parallel plane: depth 600 mm everywhere, lit over most of the image",
          "[sim][geometry]") {
  const auto sensor = SimulatedSensor::create(planeAt(600));
  const cv::Mat& depth = sensor->groundTruth().depth_mm;
  REQUIRE(depth.size() == cv::Size(1440, 1080));
  double max_error = 0;
  int hits = 0;
  for (int r = 0; r < depth.rows; ++r)
    for (int c = 0; c < depth.cols; ++c) {
      const float z = depth.at<float>(r, c);
      if (std::isnan(z)) continue;
      ++hits;
      max_error = std::max(max_error, std::abs(z - 600.0));
    }
  CHECK(hits == int(depth.total()));
  CHECK(max_error < 1e-3);
  const double lit = litFraction(*sensor);
  INFO("lit fraction at 600 mm: " << lit);
  CHECK(lit > 0.95);
}

TEST_CASE("tilted plane and sphere match the analytic intersections", "[sim][geometry]") {
  SimConfig config = realisticConfig();
  const SimPlane tilted{{0, 0, 700}, Eigen::Vector3d(0.3, -0.2, -1.0), 0.7};
  const SimSphere sphere{{30, -20, 500}, 80, 0.9};
  config.scene.planes = {tilted};
  config.scene.spheres = {sphere};
  const auto sensor = SimulatedSensor::create(config);
  const Eigen::Vector3d n = tilted.normal.normalized();

  int on_sphere = 0, on_plane = 0;
  for (int r = 0; r < 1080; r += 37)
    for (int c = 0; c < 1440; c += 41) {
      const Eigen::Vector3d ray = cameraRay(config, r, c);
      // Analytic: plane s = n.p / n.d; sphere: nearer root of |s d - c|^2 = r^2.
      const double s_plane = n.dot(tilted.point) / n.dot(ray);
      const double a = ray.squaredNorm(), b = ray.dot(sphere.center);
      const double disc = b * b - a * (sphere.center.squaredNorm() - sphere.radius * sphere.radius);
      double expected_s = s_plane;
      bool sphere_hit = false;
      if (disc >= 0 && (b - std::sqrt(disc)) / a < s_plane) {
        expected_s = (b - std::sqrt(disc)) / a;
        sphere_hit = true;
      }
      const Eigen::Vector3d expected = expected_s * ray;
      const Eigen::Vector3d got = gtPoint(*sensor, r, c);
      INFO("pixel (" << c << ", " << r << ")");
      REQUIRE((got - expected).norm() < 1e-3);
      CHECK(std::abs(sensor->groundTruth().depth_mm.at<float>(r, c) - expected.z()) < 1e-3);
      if (sphere_hit) {
        ++on_sphere;
        CHECK(std::abs((got - sphere.center).norm() - sphere.radius) < 1e-3);
      } else {
        ++on_plane;
        CHECK(std::abs(n.dot(got - tilted.point)) < 1e-3);
      }
    }
  CHECK(on_sphere > 20);
  CHECK(on_plane > 200);
}

TEST_CASE("setMotion moves the sensor: the view equals the scene moved the other way",
          "[sim][geometry]") {
  SimConfig config = realisticConfig();
  config.scene.planes = {SimPlane{{0, 0, 700}, Eigen::Vector3d(0.3, -0.2, -1.0), 0.7}};
  config.scene.spheres = {SimSphere{{30, -20, 500}, 80, 0.9}};
  const auto sensor = SimulatedSensor::create(config);
  Eigen::Isometry3d base = Eigen::Isometry3d::Identity();
  base.linear() = Eigen::AngleAxisd(degrees(2), Eigen::Vector3d::UnitY()).toRotationMatrix();
  base.translation() = Eigen::Vector3d(25, -10, 5);
  sl::drivers::SimMotion motion;
  motion.velocity_mm_s = Eigen::Vector3d(0, 30, 0);
  sensor->setMotion(base, motion);
  // Image 3 is seen from base * (0, 3 mm, 0): a static sensor looking at the
  // scene moved by the inverse of that pose sees the same.
  Eigen::Isometry3d at3 = base;
  at3.translation() += base.linear() * Eigen::Vector3d(0, 3, 0);
  SimConfig moved_config = config;
  moved_config.scene = {};
  sl::drivers::appendTransformed(moved_config.scene, config.scene, at3.inverse());
  const auto moved = SimulatedSensor::create(moved_config);
  const sl::drivers::SimGroundTruth got = sensor->groundTruthAt(0, 3);
  int compared = 0;
  for (int r = 0; r < 1080; r += 53)
    for (int c = 0; c < 1440; c += 61) {
      const float a = got.depth_mm.at<float>(r, c), b = moved->groundTruth().depth_mm.at<float>(r, c);
      REQUIRE(std::isnan(a) == std::isnan(b));
      if (std::isnan(a)) continue;
      CHECK(std::abs(a - b) < 1e-3);
      ++compared;
    }
  CHECK(compared > 300);
  // Back at the configured pose, the configured view again.
  sensor->setMotion(Eigen::Isometry3d::Identity(), {});
  const cv::Mat back = sensor->groundTruthAt(0, 3).depth_mm;
  CHECK(cv::norm(back, sensor->groundTruth().depth_mm, cv::NORM_INF) < 1e-4);
}

TEST_CASE("ground-truth projector coordinates reproject consistently", "[sim][geometry]") {
  SimConfig config = planeAt(750);
  config.scene.spheres = {SimSphere{{-40, 30, 520}, 70, 0.6}};
  const auto sensor = SimulatedSensor::create(config);
  const auto& gt = sensor->groundTruth();
  int checked = 0;
  for (int r = 0; r < 1080; r += 13)
    for (int c = 0; c < 1440; c += 17) {
      const bool lit = gt.lit.at<std::uint8_t>(r, c) != 0;
      CHECK(lit == !std::isnan(gt.up.at<float>(r, c)));
      CHECK(lit == !std::isnan(gt.vp.at<float>(r, c)));
      if (!lit) continue;
      const Eigen::Vector2d p =
          config.rig.projector.project(config.rig.R * gtPoint(*sensor, r, c) + config.rig.t);
      CHECK(std::abs(p.x() - gt.up.at<float>(r, c)) < 2e-3);
      CHECK(std::abs(p.y() - gt.vp.at<float>(r, c)) < 2e-3);
      ++checked;
    }
  CHECK(checked > 3000);
}

TEST_CASE("a sphere casts its shadow where the geometry says", "[sim][shadow]") {
  // Projector at x = +160 mm: the shadow of a sphere at 350 mm on a plane at
  // 700 mm falls to the left of the sphere as the camera sees it.
  SimConfig config = planeAt(700);
  const SimSphere sphere{{40, 0, 350}, 30, 0.8};
  config.scene.spheres = {sphere};
  const auto sensor = SimulatedSensor::create(config);
  const auto& gt = sensor->groundTruth();
  const Eigen::Vector3d projector = projectorCenter(config);

  // Centre of the shadow: the line from the projector through the sphere's centre.
  const Eigen::Vector3d shadow_centre =
      projector + (sphere.center - projector) * (700.0 / sphere.center.z());
  const Eigen::Vector2d shadow_px = config.rig.camera.project(shadow_centre);
  const int sr = int(std::lround(shadow_px.y())), sc = int(std::lround(shadow_px.x()));
  REQUIRE(std::abs(gt.depth_mm.at<float>(sr, sc) - 700.0) < 1e-3);  // the plane, visible
  CHECK(gt.lit.at<std::uint8_t>(sr, sc) == 0);
  CHECK(std::isnan(gt.up.at<float>(sr, sc)));
  // 100 mm below it on the plane: lit.
  const Eigen::Vector2d lit_px =
      config.rig.camera.project(shadow_centre + Eigen::Vector3d(0, 100, 0));
  CHECK(gt.lit.at<std::uint8_t>(int(std::lround(lit_px.y())), int(std::lround(lit_px.x()))) == 255);

  // Every plane pixel around the shadow: unlit exactly when the segment to
  // the projector passes through the sphere (pixels within 0.05 mm of the
  // shadow's edge are skipped).
  int shadowed = 0, lit = 0;
  // The shadow is ~120 mm (~400 px) across.
  for (int r = std::max(sr - 400, 0); r <= std::min(sr + 400, 1079); r += 7)
    for (int c = std::max(sc - 400, 0); c <= std::min(sc + 400, 1439); c += 7) {
      if (std::abs(gt.depth_mm.at<float>(r, c) - 700.0f) > 1e-2) continue;  // sphere pixel
      const Eigen::Vector3d x = gtPoint(*sensor, r, c);
      const Eigen::Vector3d seg = projector - x;
      const double s = std::clamp((sphere.center - x).dot(seg) / seg.squaredNorm(), 0.0, 1.0);
      const double miss = (x + s * seg - sphere.center).norm() - sphere.radius;
      if (std::abs(miss) < 0.05) continue;
      const bool expect_lit = miss > 0;
      INFO("pixel (" << c << ", " << r << ")");
      CHECK((gt.lit.at<std::uint8_t>(r, c) != 0) == expect_lit);
      (expect_lit ? lit : shadowed)++;
    }
  CHECK(shadowed > 100);
  CHECK(lit > 100);
}

TEST_CASE("radiometry without noise equals the model within quantisation", "[sim][radiometry]") {
  SimConfig config = realisticConfig();
  const SimPlane tilted{{0, 0, 650}, Eigen::Vector3d(0.2, 0.1, -1.0), 0.6};
  config.scene.planes = {tilted};
  config.gain_dn_per_electron = 0;
  config.read_noise_dn = 0;
  // Pinhole optics: the model below has no defocus (see test_sim_optics).
  config.camera_lens.f_number = 0;
  config.projector_lens.f_number = 0;
  const int bit_depth = GENERATE(8, 12, 16);
  config.bit_depth = bit_depth;
  const auto sensor = SimulatedSensor::create(config);
  const auto& gt = sensor->groundTruth();
  const auto images = sl::pipeline::generatePatternImages(config.patterns[1]);
  const double to_output = ((1 << bit_depth) - 1) / 255.0;

  for (int frame : {0, 2, 4}) {
    const cv::Mat image = sensor->render("3+3_vertical", frame, 7);
    REQUIRE(image.type() == (bit_depth == 8 ? CV_8UC1 : CV_16UC1));
    int checked = 0;
    for (int r = 5; r < 1080; r += 29)
      for (int c = 3; c < 1440; c += 31) {
        const double pixel =
            bit_depth == 8 ? image.at<std::uint8_t>(r, c) : image.at<std::uint16_t>(r, c);
        double expected = config.ambient_dn * tilted.albedo;
        if (gt.lit.at<std::uint8_t>(r, c))
          expected =
              modelSignal(*sensor, images[frame], tilted.normal.normalized(), tilted.albedo, r, c);
        INFO("bit depth " << bit_depth << " frame " << frame << " pixel (" << c << ", " << r
                          << ")");
        CHECK(std::abs(pixel - expected * to_output) <= 0.5 + 1e-4 * expected * to_output);
        ++checked;
      }
    CHECK(checked > 1500);
  }
}

TEST_CASE("noise has variance gain * signal + read^2", "[sim][radiometry]") {
  SimConfig config = planeAt(600);
  config.gain_dn_per_electron = 0.25;
  config.read_noise_dn = 1.5;
  const auto sensor = SimulatedSensor::create(config);
  SimConfig quiet = config;
  quiet.gain_dn_per_electron = 0;
  quiet.read_noise_dn = 0;
  // Noise-free reference with the same geometry.
  const auto reference = SimulatedSensor::create(quiet);

  // A 20x20 block in the middle of the image, frame 4 (unit-frequency set,
  // at 3/4 of its peak there).
  const cv::Rect block(700, 520, 20, 20);
  const cv::Mat expected = reference->render("3+3_horizontal", 4, 0)(block);
  constexpr int kSeeds = 120;
  cv::Mat sum(block.size(), CV_64FC1, cv::Scalar(0)), sum_sq = sum.clone();
  for (int seed = 0; seed < kSeeds; ++seed) {
    cv::Mat sample;
    sensor->render("3+3_horizontal", 4, 1000 + seed)(block).convertTo(sample, CV_64FC1);
    sum += sample;
    sum_sq += sample.mul(sample);
  }
  double measured_var = 0, model_var = 0, mean_bias = 0;
  for (int r = 0; r < block.height; ++r)
    for (int c = 0; c < block.width; ++c) {
      const double mean = sum.at<double>(r, c) / kSeeds;
      measured_var += (sum_sq.at<double>(r, c) - kSeeds * mean * mean) / (kSeeds - 1);
      const double signal = expected.at<std::uint8_t>(r, c);
      // + 1/12: the variance of rounding to integers.
      model_var += config.gain_dn_per_electron * signal +
                   config.read_noise_dn * config.read_noise_dn + 1.0 / 12.0;
      mean_bias += mean - signal;
    }
  const double n = block.area();
  INFO("measured std " << std::sqrt(measured_var / n) << " model std " << std::sqrt(model_var / n));
  CHECK(std::sqrt(measured_var / n) == Approx(std::sqrt(model_var / n)).epsilon(0.10));
  CHECK(std::abs(mean_bias / n) < 0.5);  // noise is zero-mean
  CHECK(cv::mean(expected)[0] > 60);     // a well-lit region: shot noise dominates
}

TEST_CASE("saturation clamps at full scale", "[sim][radiometry]") {
  SimConfig config = planeAt(350);
  config.projector_brightness_dn = 2000;
  SECTION("8 bit") {
    const auto sensor = SimulatedSensor::create(config);
    const cv::Mat image = sensor->render("3+3_horizontal", 3, 1);
    double min_value, max_value;
    cv::minMaxLoc(image, &min_value, &max_value);
    CHECK(max_value == 255);
    CHECK(cv::countNonZero(image == 255) > int(image.total() / 4));
  }
  SECTION("12 bit") {
    config.bit_depth = 12;
    const auto sensor = SimulatedSensor::create(config);
    const cv::Mat image = sensor->render("3+3_horizontal", 3, 1);
    REQUIRE(image.type() == CV_16UC1);
    double min_value, max_value;
    cv::minMaxLoc(image, &min_value, &max_value);
    CHECK(max_value == 4095);
  }
}

TEST_CASE("rendering is deterministic in the noise seed", "[sim][radiometry]") {
  const auto sensor = SimulatedSensor::create(planeAt(600));
  const cv::Mat a = sensor->render("3+3_horizontal", 1, 42);
  const cv::Mat b = sensor->render("3+3_horizontal", 1, 42);
  const cv::Mat c = sensor->render("3+3_horizontal", 1, 43);
  CHECK(cv::norm(a, b, cv::NORM_INF) == 0);
  CHECK(cv::countNonZero(a != c) > int(a.total() / 2));
  CHECK_THROWS_AS(sensor->render("nope", 0, 1), std::invalid_argument);
  CHECK_THROWS_AS(sensor->render("3+3_horizontal", 6, 1), std::out_of_range);
}

TEST_CASE("invalid configurations name the bad field", "[sim][config]") {
  auto throwsNaming = [](SimConfig c, const std::string& field) {
    INFO("field " << field);
    CHECK_THROWS_WITH(SimulatedSensor::create(std::move(c)), Catch::Contains(field));
  };
  SimConfig c = planeAt(600);
  c.rig.camera.width = 0;
  throwsNaming(c, "rig.camera.width");
  c = planeAt(600);
  c.rig.projector.fx = 0;
  throwsNaming(c, "rig.projector.fx");
  c = planeAt(600);
  c.camera_fps = 0;
  throwsNaming(c, "camera_fps");
  c = planeAt(600);
  c.bit_depth = 17;
  throwsNaming(c, "bit_depth");
  c = planeAt(600);
  c.scene.planes[0].albedo = 1.5;
  throwsNaming(c, "scene.planes[0].albedo");
  c = planeAt(600);
  c.scene.planes[0].normal = Eigen::Vector3d::Zero();
  throwsNaming(c, "scene.planes[0].normal");
  c = planeAt(600);
  c.scene.spheres = {SimSphere{{0, 0, 500}, 0, 0.5}};
  throwsNaming(c, "scene.spheres[0].radius");
  c = planeAt(600);
  c.patterns.clear();
  throwsNaming(c, "patterns");
  c = planeAt(600);
  c.patterns[1].name = c.patterns[0].name;
  throwsNaming(c, "patterns[1].name");
  c = planeAt(600);
  c.patterns[0].frequencies = {0.0, 1.0};
  throwsNaming(c, "patterns[0]");
  c = planeAt(600);
  c.patterns[0].projector_width = 912;
  throwsNaming(c, "patterns[0].projector_width");
  c = planeAt(600);
  c.rig.R(0, 0) = 2;
  throwsNaming(c, "rig.R");
  c = planeAt(600);
  c.read_noise_dn = -1;
  throwsNaming(c, "read_noise_dn");
  CHECK_THROWS_AS(SimulatedSensor::create(c), std::invalid_argument);
}

namespace {

// The live tests use the realistic camera: rendering (~6 ms in Release) keeps
// up with 60-120 fps; in a debug build it may not, which only the drop test
// would notice, and it allows for it.
SimConfig liveConfig(double fps) {
  SimConfig c = planeAt(600);
  c.camera_fps = fps;
  return c;
}

std::int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

TEST_CASE("live: two 3+3 sequences arrive on schedule, then nothing", "[sim][live]") {
  constexpr double kFps = 60;
  const auto sensor = SimulatedSensor::create(liveConfig(kFps));
  auto camera = sensor->camera();
  auto projector = sensor->projector();
  auto triggers = sensor->triggerSource();
  REQUIRE(projector->sequences().size() == 2);
  CHECK(projector->sequences()[0].frame_count == 6);

  camera->start();
  auto frames_future = std::async(std::launch::async, [&] {
    std::vector<sl::pipeline::Frame> frames;
    while (auto f = camera->grab(300ms)) frames.push_back(std::move(*f));
    return frames;
  });
  auto triggers_future = std::async(std::launch::async, [&] {
    std::vector<sl::drivers::TriggerEvent> events;
    while (auto e = triggers->next(300ms)) events.push_back(*e);
    return events;
  });
  projector->select("3+3_horizontal");
  const std::int64_t started = nowNs();
  projector->start(2);
  CHECK_THROWS_AS(projector->select("3+3_vertical"), std::logic_error);
  CHECK_THROWS_AS(projector->start(1), std::logic_error);

  // The futures end by their own timeouts; the watchdog only reports.
  REQUIRE(frames_future.wait_for(sl::test::scaledBound(5s)) == std::future_status::ready);
  REQUIRE(triggers_future.wait_for(sl::test::scaledBound(5s)) == std::future_status::ready);
  const auto frames = frames_future.get();
  const auto events = triggers_future.get();

  REQUIRE(events.size() == 2);
  const std::int64_t t0 = events[0].stamp_ns;
  CHECK(t0 - started >= 20'000'000);
  CHECK(t0 - started < 25'000'000);
  const double dt = 1e9 / kFps;
  for (std::size_t k = 0; k < events.size(); ++k) {
    CHECK(events[k].sequence_index == k);
    CHECK(std::abs(double(events[k].stamp_ns - t0) - double(k) * 6 * dt) < 1e3);
  }
  REQUIRE(frames.size() == 12);
  for (std::size_t j = 0; j < frames.size(); ++j) {
    INFO("frame " << j);
    CHECK(std::abs(double(frames[j].stamp_ns - t0) - double(j) * dt) < 1e3);
    CHECK(frames[j].frame_id == frames[0].frame_id + j);
    CHECK(frames[j].bit_depth == 8);
    CHECK(frames[j].image.size() == cv::Size(1440, 1080));
  }
  const auto counters = sensor->counters();
  CHECK(counters.frames_delivered == 12);
  CHECK(counters.frames_dropped == 0);
  CHECK(counters.triggers_delivered == 2);

  // The live images are those of render() with the frame's seed: the pattern
  // is visible (frame 0 and frame 1 differ by their phase shift).
  CHECK(cv::norm(frames[0].image, frames[1].image, cv::NORM_L1) / frames[0].image.total() > 5);

  // After the finite schedule the projector can be reconfigured.
  CHECK_NOTHROW(projector->select("3+3_vertical"));
  camera->stop();
}

TEST_CASE("live: stop wakes blocked calls; restart begins a new schedule", "[sim][live]") {
  const auto sensor = SimulatedSensor::create(liveConfig(120));
  auto camera = sensor->camera();
  auto projector = sensor->projector();
  auto triggers = sensor->triggerSource();

  CHECK_THROWS_AS(projector->select("unknown"), std::invalid_argument);
  CHECK_THROWS_AS(projector->start(-1), std::invalid_argument);

  SECTION("camera stop wakes grab") {
    camera->start();
    auto grabbed = std::async(std::launch::async, [&] { return camera->grab(3s); });
    std::this_thread::sleep_for(50ms);
    const auto stopped_at = std::chrono::steady_clock::now();
    camera->stop();
    REQUIRE(grabbed.wait_for(3500ms) == std::future_status::ready);
    CHECK(std::chrono::steady_clock::now() - stopped_at < sl::test::scaledBound(100ms));
    CHECK_FALSE(grabbed.get().has_value());
    CHECK_FALSE(camera->grab(10ms).has_value());  // disarmed
  }
  SECTION("trigger stop wakes next") {
    auto next = std::async(std::launch::async, [&] { return triggers->next(3s); });
    std::this_thread::sleep_for(50ms);
    const auto stopped_at = std::chrono::steady_clock::now();
    triggers->stop();
    REQUIRE(next.wait_for(3500ms) == std::future_status::ready);
    CHECK(std::chrono::steady_clock::now() - stopped_at < sl::test::scaledBound(100ms));
    CHECK_FALSE(next.get().has_value());
  }
  SECTION("projector stop ends an endless schedule; start begins a new one") {
    camera->start();
    projector->start(0);
    auto first = camera->grab(500ms);
    REQUIRE(first.has_value());
    auto trigger = triggers->next(500ms);
    REQUIRE(trigger.has_value());
    CHECK(trigger->stamp_ns == first->stamp_ns);
    projector->stop();
    // Frames exposed before stop() may still be buffered; then nothing.
    int after_stop = 0;
    while (camera->grab(100ms)) ++after_stop;
    CHECK(after_stop <= 8);

    projector->select("3+3_vertical");
    const std::int64_t restarted = nowNs();
    projector->start(1);
    auto again = camera->grab(500ms);
    REQUIRE(again.has_value());
    CHECK(again->stamp_ns >= restarted + 20'000'000);
    CHECK(again->frame_id > first->frame_id);
    auto trigger2 = triggers->next(500ms);
    REQUIRE(trigger2.has_value());
    CHECK(trigger2->sequence_index == 0);
    CHECK(trigger2->stamp_ns == again->stamp_ns);
    camera->stop();
    projector->stop();
  }
}

TEST_CASE("live: a slow consumer loses the oldest frames, whole sequences, counted", "[sim][live]") {
  const auto sensor = SimulatedSensor::create(liveConfig(120));
  auto camera = sensor->camera();
  auto projector = sensor->projector();
  camera->start();
  projector->start(0);
  std::this_thread::sleep_for(250ms);  // ~27 frames exposed, none grabbed
  auto first = camera->grab(500ms);
  REQUIRE(first.has_value());
  const auto dropped = sensor->counters().frames_dropped;
  CHECK(dropped >= 10);
  CHECK(first->frame_id == dropped);  // ids count exposures, dropped ones too
  // Dropped up to a sequence start: the frames delivered complete sequences.
  CHECK(first->frame_id % 6 == 0);
  // Gaps in the frame ids are exactly the frames dropped in between (none
  // unless rendering the first frame took longer than the buffer lasts).
  auto second = camera->grab(500ms);
  REQUIRE(second.has_value());
  CHECK(second->frame_id == first->frame_id + 1 + (sensor->counters().frames_dropped - dropped));
  CHECK(second->stamp_ns > first->stamp_ns);
  projector->stop();
  camera->stop();
}

// Software triggering: the projector holds one pattern, a triggered camera
// exposes it at once and delivers it one frame interval later.
TEST_CASE("live: software trigger grabs the held pattern", "[sim][live]") {
  constexpr double kFps = 60;
  const auto sensor = SimulatedSensor::create(liveConfig(kFps));
  auto camera = sensor->camera();
  auto projector = sensor->projector();
  REQUIRE(camera->hasSoftwareTrigger());
  REQUIRE(projector->canProjectSingle());
  CHECK_THROWS_AS(camera->triggerSoftware(), std::logic_error);  // not started
  camera->start();
  CHECK_THROWS_AS(camera->triggerSoftware(), std::logic_error);  // nothing projected
  CHECK_THROWS_AS(projector->projectSingle(6), std::out_of_range);
  projector->select("3+3_horizontal");
  for (int k : {4, 1}) {
    projector->projectSingle(k);
    const std::int64_t before = nowNs();
    camera->triggerSoftware();
    const auto frame = camera->grab(500ms);
    const std::int64_t after = nowNs();
    REQUIRE(frame.has_value());
    INFO("pattern frame " << k);
    CHECK(frame->stamp_ns >= before);
    CHECK(after - frame->stamp_ns >= std::int64_t(1e9 / kFps));  // exposed for a frame interval
    // The image is that pattern frame (up to noise), not another one.
    std::vector<double> distance;
    for (int i = 0; i < 6; ++i)
      distance.push_back(cv::norm(frame->image, sensor->render("3+3_horizontal", i, 7),
                                  cv::NORM_L1) / double(frame->image.total()));
    CHECK(std::min_element(distance.begin(), distance.end()) - distance.begin() == k);
    CHECK(distance[k] < 2.0);
  }
  CHECK_FALSE(camera->grab(50ms).has_value());  // one frame per trigger
  projector->stop();
  CHECK_THROWS_AS(camera->triggerSoftware(), std::logic_error);  // stop() ends the held pattern
  camera->stop();
}
