#include "common.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <stdexcept>

#include "sl/drivers/sim_rig.h"
#include "sl/pipeline/codec.h"

namespace sl::eval {

pipeline::CameraProjectorCalibration rig(const Eigen::Vector3d& projector_center, double cross_mm) {
  pipeline::CameraProjectorCalibration r;
  r.camera = drivers::simCameraModel();
  r.projector = drivers::simProjectorModel();
  // Rotate the projector's z axis onto the direction towards (0, 0, cross).
  const Eigen::Vector3d axis = (Eigen::Vector3d(0, 0, cross_mm) - projector_center).normalized();
  r.R = Eigen::Quaterniond::FromTwoVectors(axis, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  r.t = -r.R * projector_center;
  return r;
}

drivers::SimConfig baseConfig(const pipeline::CameraProjectorCalibration& rig,
                              const pipeline::PatternSpec& pattern, const EvalOptions& options) {
  drivers::SimConfig c;
  c.rig = rig;
  c.patterns = {pattern};
  c.camera_fps = kFps;
  // Radiometry: SimConfig's defaults, which are those of config/sim.yaml
  // (test_config checks that they agree).
  c.projector_gamma = options.projector_gamma;
  return c;
}

pipeline::PatternSpec pattern33(const std::string& name, pipeline::Direction direction) {
  pipeline::PhaseShift33Pattern p;
  p.name = name;
  p.direction = direction;
  p.fringes = kFringes;
  return pipeline::toSpec(p);
}

pipeline::TriangulatorOptions evalTriangulation(pipeline::TriangulatorOptions::Use use) {
  pipeline::TriangulatorOptions t;
  t.use = use;
  t.min_depth_mm = 200;
  t.max_depth_mm = 1500;
  return t;
}

std::vector<cv::Mat> renderScan(const drivers::SimulatedSensor& sensor, const std::string& pattern,
                                int frames, std::uint64_t seed) {
  std::vector<cv::Mat> images;
  for (int i = 0; i < frames; ++i)
    images.push_back(sensor.render(pattern, i, seed * 1000 + static_cast<std::uint64_t>(i) + 1));
  return images;
}

cv::Mat depthOf(const pipeline::PointCloud& cloud) {
  cv::Mat z(cloud.height, cloud.width, CV_32FC1);
  for (int r = 0; r < cloud.height; ++r)
    for (int c = 0; c < cloud.width; ++c)
      z.at<float>(r, c) = cloud.points[static_cast<std::size_t>(r) * cloud.width + c].z;
  return z;
}

cv::Mat phaseNoiseFloor(const pipeline::ProjectorMaps& maps, const drivers::SimConfig& config,
                        const pipeline::PatternSpec& spec, bool columns) {
  const double full_scale = std::pow(2.0, config.bit_depth) - 1;
  const double to8 = 255.0 / full_scale;  // camera DN -> 8-bit DN
  const double period = spec.finestPeriod(spec.axisLength(columns));
  const double read_sq = config.read_noise_dn * config.read_noise_dn;
  const double quantisation_sq = to8 * to8 / 12.0;
  cv::Mat sigma(maps.modulation.size(), CV_32FC1, cv::Scalar(kNaN));
  for (int r = 0; r < sigma.rows; ++r)
    for (int c = 0; c < sigma.cols; ++c) {
      const double a = maps.offset.at<float>(r, c) * to8, b = maps.modulation.at<float>(r, c) * to8;
      if (!(b > 0)) continue;
      const double sigma_i =
          std::sqrt(config.gain_dn_per_electron * std::max(a, 0.0) + read_sq + quantisation_sq);
      const double sigma_phi = std::sqrt(2.0 / spec.steps) * sigma_i / b;
      sigma.at<float>(r, c) = static_cast<float>(sigma_phi * period / (2 * std::numbers::pi));
    }
  return sigma;
}

EvalOptions withDefaultScans(const EvalOptions& options, const std::string& experiment) {
  EvalOptions o = options;
  if (o.scans <= 0) o.scans = defaultScans(experiment);
  return o;
}

double radiansOf(double degrees) { return degrees * std::numbers::pi / 180.0; }

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto k = static_cast<std::size_t>(std::clamp(q, 0.0, 1.0) * double(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

std::string fmt(double v, int decimals) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", decimals, v);
  return buffer;
}

std::string plotPath(const EvalOptions& options, const std::string& name) {
  std::filesystem::create_directories(options.out_dir);
  return (std::filesystem::path(options.out_dir) / name).string();
}

SphereFit fitSphere(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 4) throw std::invalid_argument("fitSphere: needs at least 4 points");
  // Algebraic start: |p|^2 = 2 c.p + (r^2 - |c|^2), linear in (c, d), about
  // the centroid for conditioning.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) mean += p;
  mean /= double(points.size());
  Eigen::Matrix4d AtA = Eigen::Matrix4d::Zero();
  Eigen::Vector4d Atb = Eigen::Vector4d::Zero();
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector3d q = p - mean;
    const Eigen::Vector4d a(2 * q.x(), 2 * q.y(), 2 * q.z(), 1);
    AtA += a * a.transpose();
    Atb += a * q.squaredNorm();
  }
  const Eigen::Vector4d x = AtA.ldlt().solve(Atb);
  SphereFit fit;
  fit.center = mean + x.head<3>();
  fit.radius = std::sqrt(std::max(x[3] + x.head<3>().squaredNorm(), 0.0));
  // Gauss-Newton on the radial distances; parameters (c, r).
  Eigen::Matrix4d JtJ;
  double sum_sq = 0;
  for (int iteration = 0; iteration < 20; ++iteration) {
    JtJ.setZero();
    Eigen::Vector4d Jtr = Eigen::Vector4d::Zero();
    sum_sq = 0;
    for (const Eigen::Vector3d& p : points) {
      const Eigen::Vector3d d = p - fit.center;
      const double n = d.norm();
      const double residual = n - fit.radius;
      Eigen::Vector4d j;
      j.head<3>() = -d / n;
      j[3] = -1;
      JtJ += j * j.transpose();
      Jtr += j * residual;
      sum_sq += residual * residual;
    }
    const Eigen::Vector4d step = JtJ.ldlt().solve(-Jtr);
    fit.center += step.head<3>();
    fit.radius += step[3];
    if (step.norm() < 1e-10) break;
  }
  const double variance = sum_sq / double(std::max<std::size_t>(points.size() - 4, 1));
  const Eigen::Matrix4d covariance = variance * JtJ.inverse();
  fit.center_covariance = covariance.topLeftCorner<3, 3>();
  fit.radius_std = std::sqrt(covariance(3, 3));
  return fit;
}

PlaneFit fitPlane(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 3) throw std::invalid_argument("fitPlane: needs at least 3 points");
  PlaneFit fit;
  for (const Eigen::Vector3d& p : points) fit.point += p;
  fit.point /= double(points.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : points)
    covariance += (p - fit.point) * (p - fit.point).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  fit.normal = solver.eigenvectors().col(0);  // smallest eigenvalue
  return fit;
}

double range(const std::vector<double>& values) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  return *hi - *lo;
}

double discardThreshold(const std::vector<double>& values, double drop, double* median) {
  *median = percentile(values, 0.5);
  std::vector<double> deviation(values.size());
  for (std::size_t i = 0; i < values.size(); ++i) deviation[i] = std::abs(values[i] - *median);
  const auto discarded = static_cast<std::size_t>(drop * double(values.size()));
  return percentile(deviation,
                    1.0 - double(discarded) / double(std::max<std::size_t>(values.size(), 2) - 1));
}

double rangeWithout(const std::vector<double>& values, double drop) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  double median = 0;
  const double threshold = discardThreshold(values, drop, &median);
  double lo = median, hi = median;
  for (double v : values)
    if (std::abs(v - median) <= threshold) lo = std::min(lo, v), hi = std::max(hi, v);
  return hi - lo;
}

}  // namespace sl::eval
