// Motion compensation through the camera's lens model on the simulator: a
// lateral scan of a flat textured wall, the sensor moving along the fringes,
// decoded and triangulated as the daemon does. Shifting the distorted frames
// as a whole twists the cloud (a depth error ~ x y: the pixels off the image
// axes see points moved across the fringes); compensating in undistorted
// coordinates must not (README, sl_eval wall: "Why the drift").
#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "sl/drivers/sim.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/motion_compensation.h"
#include "sl/pipeline/triangulator.h"
#include "support/sim_rig.h"

namespace {

using sl::pipeline::MotionCompensationOptions;
using sl::pipeline::MotionCompensator;

// Least-squares fit of the depth error e = c0 + c1 x + c2 y + c3 x^2 + c4 y^2
// + c5 x y (mm; x, y the point in the camera frame in units of 100 mm) over
// the valid points within 1 mm of the truth, every 2nd pixel.
struct Shape {
  Eigen::Matrix<double, 6, 1> c = Eigen::Matrix<double, 6, 1>::Zero();
  long long points = 0;
  double rms_mm = 0;  // of e around the fit
};

Shape fitShape(const sl::pipeline::PointCloud& cloud, const cv::Mat& truth_depth) {
  Eigen::Matrix<double, 6, 6> normal = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
  std::vector<std::pair<Eigen::Matrix<double, 6, 1>, double>> samples;
  for (int r = 0; r < cloud.height; r += 2)
    for (int c = 0; c < cloud.width; c += 2) {
      const auto& p = cloud.points[std::size_t(r) * std::size_t(cloud.width) + std::size_t(c)];
      const double e = double(p.z) - double(truth_depth.at<float>(r, c));
      if (!std::isfinite(e) || std::abs(e) > 1.0) continue;
      const double x = p.x / 100.0, y = p.y / 100.0;
      Eigen::Matrix<double, 6, 1> b;
      b << 1, x, y, x * x, y * y, x * y;
      normal += b * b.transpose();
      rhs += b * e;
      samples.push_back({b, e});
    }
  Shape s;
  s.points = static_cast<long long>(samples.size());
  if (s.points < 100) return s;
  s.c = normal.ldlt().solve(rhs);
  double ss = 0;
  for (const auto& [b, e] : samples) ss += (e - b.dot(s.c)) * (e - b.dot(s.c));
  s.rms_mm = std::sqrt(ss / double(s.points));
  return s;
}

}  // namespace

TEST_CASE("motion compensation through the lens model: a lateral scan of a plane is not twisted",
          "[sim][motion][lens]") {
  // config/sim.yaml's rig: projector 150 mm beside the camera (yawed about
  // y), 3+3 encoding projector columns, camera lens k1 = -0.08. The sensor
  // moves along the camera's y (the projector's y: along the fringes) at
  // 60 mm/s, 2 mm per image at 30 fps (config/sim-motion.yaml's speed),
  // 450 mm from a flat wall whose albedo carries a texture for the
  // correlation.
  sl::drivers::SimConfig c = sl::test::simConfig33("3+3_horizontal", 40);
  REQUIRE(c.rig.camera.hasDistortion());
  sl::drivers::SimHeightField wall;
  wall.origin = Eigen::Vector3d(0, 0, 450);
  wall.width_mm = 600;
  wall.length_mm = 480;
  wall.cell_mm = 2;
  wall.heights_mm = cv::Mat::zeros(241, 301, CV_32FC1);
  cv::Mat noise(241 * 2, 301 * 2, CV_32FC1);
  cv::RNG(5).fill(noise, cv::RNG::NORMAL, 0, 1);
  cv::GaussianBlur(noise, wall.albedo_texture, cv::Size(0, 0), 2.0);
  cv::normalize(wall.albedo_texture, wall.albedo_texture, 0.45, 0.9, cv::NORM_MINMAX);
  c.scene.height_fields = {wall};
  c.motion.velocity_mm_s = {0, 60, 0};
  const sl::pipeline::PatternSpec spec = c.patterns.front();
  const sl::pipeline::Decoder decoder(spec, sl::pipeline::DecoderOptions{});
  MotionCompensationOptions options;
  options.axis = MotionCompensationOptions::Axis::kY;

  // One scan of the simulator `config` motion-compensated by `compensator`
  // (given the models of `cameras`), its depth errors' shape.
  auto scan = [&](const sl::drivers::SimConfig& config,
                  const std::map<std::string, sl::pipeline::PinholeModel>& cameras,
                  sl::pipeline::MotionEstimate& estimate) {
    const auto sensor = sl::drivers::SimulatedSensor::create(config);
    const int frames = spec.frameCount();
    sl::pipeline::ImageSet set;
    set.pattern_name = spec.name;
    set.cameras.resize(1);
    set.cameras[0].camera_id = "sim";
    for (int i = 0; i < frames; ++i) {
      set.cameras[0].frames.push_back(sensor->render(spec.name, i, 300 + i));
      set.cameras[0].stamps_ns.push_back(std::int64_t(i) * 1'000'000'000 / 30);
    }
    sl::pipeline::TriangulatorOptions t;
    t.use = sl::pipeline::TriangulatorOptions::Use::kColumns;
    const sl::pipeline::Triangulator triangulator(config.rig, t);
    const auto aligned = MotionCompensator(options, cameras).compensate(set, &estimate);
    // The truth at the reference frame (the compensator's default, the middle).
    const cv::Mat truth = sensor->groundTruthAt(0, frames / 2).depth_mm;
    return fitShape(triangulator.triangulate(decoder.decode(aligned->cameras[0].frames, 8)), truth);
  };
  sl::pipeline::MotionEstimate whole_estimate, lens_estimate, ideal_estimate;
  const Shape whole = scan(c, {}, whole_estimate);
  const Shape lens = scan(c, {{"sim", c.rig.camera}}, lens_estimate);
  // What is left through the lens is the projector's distortion (k1 0.02,
  // k2 -0.01): a scene point moving along the projector's y moves across
  // its distorted columns too (~ x y), which no resampling of the camera's
  // images undoes. With an undistorted projector nothing is left.
  sl::drivers::SimConfig ideal_projector = c;
  ideal_projector.rig.projector.distortion = {0, 0, 0, 0, 0};
  const Shape ideal = scan(ideal_projector, {{"sim", c.rig.camera}}, ideal_estimate);
  WARN("undistorted projector, through the lens: x y term " << ideal.c[5] << " mm, rms "
                                                            << ideal.rms_mm << " mm");
  WARN("whole frames shifted: x y term " << whole.c[5] << " mm, x^2 " << whole.c[3] << ", y^2 "
                                          << whole.c[4] << ", rms " << whole.rms_mm << " mm, "
                                          << whole.points << " points");
  WARN("through the lens:     x y term " << lens.c[5] << " mm, x^2 " << lens.c[3] << ", y^2 "
                                          << lens.c[4] << ", rms " << lens.rms_mm << " mm, "
                                          << lens.points << " points");
  WARN("shifts of frame 0: " << whole_estimate.shifts_px[0][0] << " / " << lens_estimate.shifts_px[0][0]
                             << " px");
  // Both registered the motion (2 mm per image at 450 mm: 10.7 px).
  CHECK(std::abs(std::abs(lens_estimate.shifts_px[0][0]) - 3 * 2 * 2400 / 450.0) < 0.5);
  // The twist (x y term, mm at x = y = 100 mm): measured 0.092 with whole
  // frames shifted, 0.026 through the lens, 0.020 for a pinhole camera with
  // whole frames shifted (the projector's part), 0.0005 through the lens with
  // an undistorted projector.
  CHECK(std::abs(whole.c[5]) > 0.07);
  CHECK(std::abs(lens.c[5]) < 0.035);
  CHECK(std::abs(ideal.c[5]) < 0.005);
  // Nothing else got worse, and the points are not lost.
  CHECK(lens.rms_mm <= whole.rms_mm * 1.05);
  CHECK(lens.points > whole.points * 0.97);
}
