// Per-point quality on the simulator (issue 35 item 3): the predicted depth
// sigma (pipeline/point_quality.h) against the measured depth error per band
// of predicted sigma, and the organized normals against the scene's known
// surfaces.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <utility>
#include <vector>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "common.h"  // sl_eval's simulated rig and rendering helpers
#include "sl_process/process.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/point_quality.h"
#include "sl/pipeline/triangulator.h"

namespace {

using sl::pipeline::PointCloud;

struct Scene {
  sl::pipeline::CameraProjectorCalibration calibration;
  sl::pipeline::PatternSpec spec;
  sl::drivers::SimConfig config;
};

// The precision experiment's rig (projector 150 mm to the right, axes
// crossing at 550 mm), 3+3 horizontal, a wall tilted 30 deg about the
// vertical axis (depth 430..700 mm across the image) whose albedo falls
// smoothly from 0.95 to 0.07 from top to bottom: the predicted sigma spans
// several times its smallest value.
Scene tiltedWall() {
  Scene s;
  s.calibration = sl::eval::rig({150, 0, 0}, 550);
  s.spec = sl::eval::pattern33("3+3_horizontal", sl::pipeline::Direction::kHorizontal);
  sl::eval::EvalOptions options;
  s.config = sl::eval::baseConfig(s.calibration, s.spec, options);
  const double tilt = 30 * std::numbers::pi / 180;
  sl::drivers::SimPlane wall;
  wall.point = {0, 0, 550};
  wall.normal = {std::sin(tilt), 0, -std::cos(tilt)};
  wall.albedo = 0.5;
  sl::drivers::SimPlaneTexture texture;
  texture.albedo = cv::Mat(256, 256, CV_32FC1);
  for (int r = 0; r < 256; ++r) texture.albedo.row(r).setTo(0.95 - 0.88 * r / 255.0);
  texture.center = wall.point;
  texture.x_axis = {1, 0, 0};
  texture.width_mm = 320;  // and as tall: about the camera's view
  wall.texture = texture;
  s.config.scene.planes = {wall};
  return s;
}

double rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s / double(v.size()));
}

}  // namespace

TEST_CASE("depth sigma: predicted matches the measured error per band of predicted sigma",
          "[metrology][quality]") {
  const Scene s = tiltedWall();
  const auto sensor = sl::drivers::SimulatedSensor::create(s.config);
  const sl::pipeline::Decoder decoder(s.spec, {});
  const sl::pipeline::Triangulator triangulator(
      s.calibration, sl::eval::evalTriangulation(sl::pipeline::TriangulatorOptions::Use::kColumns));
  sl::pipeline::CameraNoise noise;
  noise.gain_dn_per_electron = s.config.gain_dn_per_electron;
  noise.read_noise_dn = s.config.read_noise_dn;
  noise.bit_depth = s.config.bit_depth;
  const cv::Mat& truth = sensor->groundTruth().depth_mm;

  // Pool (predicted sigma, error against the truth) over a few scans.
  struct Sample {
    double sigma, error;
  };
  std::vector<Sample> samples;
  constexpr int kScans = 3;
  std::size_t sigma_without_point = 0, point_without_sigma = 0;
  for (int k = 0; k < kScans; ++k) {
    const auto maps = decoder.decode(
        sl::eval::renderScan(*sensor, s.spec.name, s.spec.frameCount(), 500 + k), 8);
    const PointCloud cloud = triangulator.triangulate(maps);
    const cv::Mat sigma = sl::pipeline::depthSigma(maps, cloud, s.calibration, s.spec, noise,
                                                   sl::pipeline::TriangulatorOptions::Use::kColumns);
    REQUIRE(sigma.size() == cv::Size(cloud.width, cloud.height));
    // Leave out a margin where the defocused projector image meets its edge.
    for (int r = 20; r < cloud.height - 20; r += 2)
      for (int c = 20; c < cloud.width - 20; c += 2) {
        const double z = cloud.points[std::size_t(r) * cloud.width + c].z;
        const double sz = sigma.at<float>(r, c), t = truth.at<float>(r, c);
        if (!std::isfinite(z)) {
          sigma_without_point += std::isfinite(sz);
          continue;
        }
        if (!std::isfinite(sz)) {
          ++point_without_sigma;
          continue;
        }
        if (!std::isfinite(t)) continue;
        samples.push_back({sz, z - t});
      }
  }
  CHECK(sigma_without_point == 0);
  CHECK(point_without_sigma == 0);
  REQUIRE(samples.size() > 100000);
  // Period errors are not noise: none expected on this scene.
  std::size_t gross = 0;
  for (const Sample& x : samples) gross += std::abs(x.error) > 1.0;
  CHECK(gross < samples.size() / 10000);

  std::sort(samples.begin(), samples.end(),
            [](const Sample& a, const Sample& b) { return a.sigma < b.sigma; });
  constexpr int kBands = 6;
  const double spread = samples[samples.size() * 99 / 100].sigma / samples[samples.size() / 100].sigma;
  std::printf("depth sigma: %zu samples, predicted 1..99 %% %.4f..%.4f mm (x%.1f)\n", samples.size(),
              samples[samples.size() / 100].sigma, samples[samples.size() * 99 / 100].sigma, spread);
  CHECK(spread > 2.0);  // the bands must differ for the test to mean something
  for (int b = 0; b < kBands; ++b) {
    const std::size_t begin = samples.size() * b / kBands, end = samples.size() * (b + 1) / kBands;
    std::vector<double> predicted, errors;
    double mean = 0;
    for (std::size_t i = begin; i < end; ++i) {
      if (std::abs(samples[i].error) > 1.0) continue;
      predicted.push_back(samples[i].sigma);
      errors.push_back(samples[i].error);
      mean += samples[i].error;
    }
    mean /= double(errors.size());
    const double ratio = rms(errors) / rms(predicted);
    std::printf("  band %d: predicted %.4f..%.4f mm RMS %.4f, measured RMS error %.4f (mean %+.4f) "
                "mm, ratio %.3f\n",
                b, samples[begin].sigma, samples[end - 1].sigma, rms(predicted), rms(errors), mean,
                ratio);
    INFO("band " << b << " predicted RMS " << rms(predicted) << " measured " << rms(errors));
    CHECK(ratio > 0.8);
    CHECK(ratio < 1.2);
  }
}

TEST_CASE("depth sigma: a 12-bit camera (noise model on the 8-bit scale, finer quantisation)",
          "[metrology][quality]") {
  Scene s = tiltedWall();
  s.config.bit_depth = 12;
  const auto sensor = sl::drivers::SimulatedSensor::create(s.config);
  const sl::pipeline::Decoder decoder(s.spec, {});
  const sl::pipeline::Triangulator triangulator(
      s.calibration, sl::eval::evalTriangulation(sl::pipeline::TriangulatorOptions::Use::kColumns));
  sl::pipeline::CameraNoise noise;
  noise.bit_depth = 12;
  const cv::Mat& truth = sensor->groundTruth().depth_mm;
  std::vector<std::pair<double, double>> samples;  // predicted sigma, error
  for (int k = 0; k < 2; ++k) {
    const auto maps = decoder.decode(
        sl::eval::renderScan(*sensor, s.spec.name, s.spec.frameCount(), 900 + k), 12);
    const PointCloud cloud = triangulator.triangulate(maps);
    const cv::Mat sigma = sl::pipeline::depthSigma(maps, cloud, s.calibration, s.spec, noise,
                                                   sl::pipeline::TriangulatorOptions::Use::kColumns);
    for (int r = 20; r < cloud.height - 20; r += 3)
      for (int c = 20; c < cloud.width - 20; c += 3) {
        const double z = cloud.points[std::size_t(r) * cloud.width + c].z, t = truth.at<float>(r, c);
        const double sz = sigma.at<float>(r, c);
        if (std::isfinite(z) && std::isfinite(t) && std::isfinite(sz) && std::abs(z - t) < 1.0)
          samples.emplace_back(sz, z - t);
      }
  }
  REQUIRE(samples.size() > 50000);
  std::sort(samples.begin(), samples.end());
  for (int b = 0; b < 3; ++b) {
    double p = 0, e = 0;
    const std::size_t begin = samples.size() * b / 3, end = samples.size() * (b + 1) / 3;
    for (std::size_t i = begin; i < end; ++i) {
      p += samples[i].first * samples[i].first;
      e += samples[i].second * samples[i].second;
    }
    const double ratio = std::sqrt(e / p);
    std::printf("12-bit band %d: predicted RMS %.4f mm, measured %.4f mm, ratio %.3f\n", b,
                std::sqrt(p / double(end - begin)), std::sqrt(e / double(end - begin)), ratio);
    CHECK(ratio > 0.8);
    CHECK(ratio < 1.2);
  }
  // The same maps read as 16-bit would make the model's 8-bit DN 16x too
  // small: a clearly wrong sigma, which is why sl_process has --camera-bits.
  noise.bit_depth = 16;
  const auto maps = decoder.decode(sl::eval::renderScan(*sensor, s.spec.name, s.spec.frameCount(), 1), 12);
  const PointCloud cloud = triangulator.triangulate(maps);
  const cv::Mat wrong = sl::pipeline::depthSigma(maps, cloud, s.calibration, s.spec, noise,
                                                 sl::pipeline::TriangulatorOptions::Use::kColumns);
  noise.bit_depth = 12;
  const cv::Mat right = sl::pipeline::depthSigma(maps, cloud, s.calibration, s.spec, noise,
                                                 sl::pipeline::TriangulatorOptions::Use::kColumns);
  const int r = cloud.height / 2, c = cloud.width / 2;
  REQUIRE(std::isfinite(right.at<float>(r, c)));
  CHECK(wrong.at<float>(r, c) > 1.5 * right.at<float>(r, c));
}

TEST_CASE("depth sigma: missing maps and codecs without a phase are refused", "[metrology][quality]") {
  const Scene s = tiltedWall();
  sl::pipeline::ProjectorMaps empty;
  CHECK_THROWS_AS(sl::pipeline::projectorCoordinateSigma(empty, s.spec, {}, true),
                  std::invalid_argument);
  sl::pipeline::ProjectorMaps maps;
  maps.offset = cv::Mat(4, 4, CV_32FC1, cv::Scalar(100));
  maps.modulation = cv::Mat(4, 4, CV_32FC1, cv::Scalar(50));
  maps.modulation.at<float>(1, 1) = 0;
  const cv::Mat sigma = sl::pipeline::projectorCoordinateSigma(maps, s.spec, {}, true);
  CHECK(std::isnan(sigma.at<float>(1, 1)));
  CHECK(sigma.at<float>(0, 0) > 0);
  // Half the modulation, twice the sigma (same offset).
  maps.modulation.at<float>(2, 2) = 25;
  const cv::Mat again = sl::pipeline::projectorCoordinateSigma(maps, s.spec, {}, true);
  CHECK(again.at<float>(2, 2) == Approx(2 * again.at<float>(0, 0)).epsilon(1e-5));
  sl::pipeline::PatternSpec gray = s.spec;
  gray.family = sl::pipeline::PatternFamily::kGrayCode;
  CHECK_THROWS_AS(sl::pipeline::projectorCoordinateSigma(maps, gray, {}, true),
                  std::invalid_argument);
}

TEST_CASE("normals: organized normals agree with the simulated plane and sphere",
          "[metrology][quality]") {
  Scene s = tiltedWall();
  // A sphere in front of the wall.
  const Eigen::Vector3d centre(-40, 20, 480);
  const double radius = 60;
  s.config.scene.spheres = {sl::drivers::SimSphere{centre, radius, 0.8}};
  const auto sensor = sl::drivers::SimulatedSensor::create(s.config);
  const sl::pipeline::Decoder decoder(s.spec, {});
  const sl::pipeline::Triangulator triangulator(
      s.calibration, sl::eval::evalTriangulation(sl::pipeline::TriangulatorOptions::Use::kColumns));
  const PointCloud cloud = triangulator.triangulate(
      decoder.decode(sl::eval::renderScan(*sensor, s.spec.name, s.spec.frameCount(), 7), 8));
  // Central differences 2 * kStep px (~3.5 mm at 550 mm) apart: the normal's
  // noise is about sqrt(2) sigma_z / that, ~2.5 deg here.
  constexpr int kStep = 6;
  const cv::Mat normals = sl::pipeline::organizedNormals(cloud, kStep, 5.0f);
  REQUIRE(normals.type() == CV_32FC3);
  const Eigen::Vector3d wall_normal = s.config.scene.planes[0].normal.normalized();
  const cv::Mat& truth = sensor->groundTruth().xyz_mm;
  std::vector<double> wall_deg, sphere_deg;
  std::size_t bad_normals = 0;
  Eigen::Vector3d wall_sum = Eigen::Vector3d::Zero();
  for (int r = 10; r < cloud.height - 10; ++r)
    for (int c = 10; c < cloud.width - 10; ++c) {
      const cv::Vec3f t = truth.at<cv::Vec3f>(r, c);
      if (!std::isfinite(t[2])) continue;
      const Eigen::Vector3d p(t[0], t[1], t[2]);
      const bool on_sphere = std::abs((p - centre).norm() - radius) < 0.5;
      const cv::Vec3f n = normals.at<cv::Vec3f>(r, c);
      if (!std::isfinite(n[0])) continue;
      const Eigen::Vector3d measured(n[0], n[1], n[2]);
      bad_normals += std::abs(measured.norm() - 1) > 1e-4;
      bad_normals += measured.dot(p) >= 0;  // must face the camera
      const Eigen::Vector3d expected = on_sphere ? Eigen::Vector3d((p - centre) / radius) : wall_normal;
      const double deg = std::acos(std::clamp(measured.dot(expected), -1.0, 1.0)) * 180 / std::numbers::pi;
      (on_sphere ? sphere_deg : wall_deg).push_back(deg);
      if (!on_sphere) wall_sum += measured;
    }
  CHECK(bad_normals == 0);
  REQUIRE(wall_deg.size() > 100000);
  REQUIRE(sphere_deg.size() > 10000);
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  // Normals across the sphere's silhouette (a depth jump of ~50 mm) would be
  // wild: max_jump leaves them NaN.
  const double wild = double(std::count_if(wall_deg.begin(), wall_deg.end(),
                                           [](double d) { return d > 20; })) /
                      double(wall_deg.size());
  const double mean_wall_deg =
      std::acos(std::clamp(wall_sum.normalized().dot(wall_normal), -1.0, 1.0)) * 180 / std::numbers::pi;
  std::printf("normals (step %d px): wall median %.3f deg, mean normal off by %.4f deg; sphere median "
              "%.3f deg; %.3f %% of the wall's normals off by > 20 deg\n",
              kStep, median(wall_deg), mean_wall_deg, median(sphere_deg), 100 * wild);
  CHECK(median(wall_deg) < 3.0);
  CHECK(mean_wall_deg < 0.1);
  CHECK(median(sphere_deg) < 3.0);
  CHECK(wild < 0.001);
  CHECK_THROWS_AS(sl::pipeline::organizedNormals(cloud, 0, 5.0f), std::invalid_argument);
}

TEST_CASE("sl_process: cloud.ply carries nx ny nz and confidence, depth_sigma.tiff written",
          "[metrology][quality]") {
  const Scene s = tiltedWall();
  const auto sensor = sl::drivers::SimulatedSensor::create(s.config);
  sl::tools::LoadedFrames frames;
  frames.frames = sl::eval::renderScan(*sensor, s.spec.name, s.spec.frameCount(), 11);
  frames.bit_depth = 8;
  sl::pipeline::TriangulatorOptions triangulation =
      sl::eval::evalTriangulation(sl::pipeline::TriangulatorOptions::Use::kColumns);
  sl::tools::ProcessResult result =
      sl::tools::processCapture(s.spec, s.calibration, frames, {}, triangulation);
  sl::pipeline::CameraNoise noise;
  sl::tools::addPointQuality(result, s.spec, s.calibration, noise, triangulation.use);
  const std::string dir = std::string(SL_BINARY_DIR) + "/test_metrology_process";
  std::filesystem::remove_all(dir);
  const std::size_t points = sl::tools::writeOutputs(result, 8, dir);
  REQUIRE(points > 1000000);
  const cv::Mat sigma = cv::imread(dir + "/depth_sigma.tiff", cv::IMREAD_UNCHANGED);
  REQUIRE(sigma.type() == CV_32FC1);
  REQUIRE(sigma.size() == result.depth_sigma.size());
  REQUIRE(sigma.isContinuous());
  REQUIRE(result.depth_sigma.isContinuous());
  // Bit for bit, NaN included.
  CHECK(std::memcmp(sigma.data, result.depth_sigma.data, sigma.total() * sizeof(float)) == 0);
  std::ifstream ply(dir + "/cloud.ply", std::ios::binary);
  std::string line, header;
  while (std::getline(ply, line) && line != "end_header") header += line + "\n";
  INFO(header);
  CHECK(header.find("property float x\nproperty float y\nproperty float z\nproperty float "
                    "intensity\nproperty float nx\nproperty float ny\nproperty float nz\nproperty "
                    "float confidence\n") != std::string::npos);
  CHECK(header.find("element vertex " + std::to_string(points) + "\n") != std::string::npos);
  // The first point's record against the maps.
  std::size_t first = 0;
  while (!std::isfinite(result.cloud.points[first].z)) ++first;
  float record[8];
  ply.read(reinterpret_cast<char*>(record), sizeof record);
  const int r = int(first) / result.cloud.width, c = int(first) % result.cloud.width;
  CHECK(record[2] == result.cloud.points[first].z);
  const cv::Vec3f n = result.normals.at<cv::Vec3f>(r, c);
  for (int k = 0; k < 3; ++k)
    CHECK((record[4 + k] == n[k] || (std::isnan(record[4 + k]) && std::isnan(n[k]))));
  CHECK(record[7] == result.depth_sigma.at<float>(r, c));
}
