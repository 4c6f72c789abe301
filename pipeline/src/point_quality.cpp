#include "sl/pipeline/point_quality.h"

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace sl::pipeline {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// sqrt(2 / N) of the family's phase estimate (docs/simulator.md).
double phaseNoiseFactor(const PatternSpec& spec) {
  switch (spec.family) {
    case PatternFamily::kPhaseShift:
    case PatternFamily::kGrayPhaseShift:
    case PatternFamily::kModulatedPhaseShift:
      return std::sqrt(2.0 / spec.steps);
    case PatternFamily::kTwoPlusOne:
      return std::sqrt(2.0);
    default:
      throw std::invalid_argument("point quality: pattern '" + spec.name +
                                  "' has no phase-noise model (Gray code or micro phase shift)");
  }
}

}  // namespace

cv::Mat projectorCoordinateSigma(const ProjectorMaps& maps, const PatternSpec& spec,
                                 const CameraNoise& noise, bool columns) {
  if (maps.offset.type() != CV_32FC1 || maps.modulation.type() != CV_32FC1 ||
      maps.offset.size() != maps.modulation.size())
    throw std::invalid_argument(
        "point quality: maps.offset and maps.modulation must be CV_32FC1 of one size");
  if (noise.bit_depth < 1 || noise.bit_depth > 16)
    throw std::invalid_argument("point quality: bit_depth must be 1..16, got " +
                                std::to_string(noise.bit_depth));
  const double factor = phaseNoiseFactor(spec);
  const double to8 = 255.0 / (std::pow(2.0, noise.bit_depth) - 1.0);  // camera DN -> 8-bit DN
  const double fixed_var = noise.read_noise_dn * noise.read_noise_dn + to8 * to8 / 12.0;
  const double period = spec.family == PatternFamily::kGrayPhaseShift
                            ? spec.stripeWidth(spec.axisLength(columns))
                            : spec.finestPeriod(spec.axisLength(columns));
  const double scale = factor * period / (2 * std::numbers::pi);
  cv::Mat sigma(maps.modulation.size(), CV_32FC1);
  for (int r = 0; r < sigma.rows; ++r) {
    const float* a = maps.offset.ptr<float>(r);
    const float* b = maps.modulation.ptr<float>(r);
    float* out = sigma.ptr<float>(r);
    for (int c = 0; c < sigma.cols; ++c) {
      const double bb = b[c] * to8;
      if (!(bb > 0)) {
        out[c] = kNaN;
        continue;
      }
      const double aa = std::max(0.0, double(a[c]) * to8);
      out[c] = static_cast<float>(scale * std::sqrt(noise.gain_dn_per_electron * aa + fixed_var) / bb);
    }
  }
  return sigma;
}

cv::Mat depthSigma(const ProjectorMaps& maps, const PointCloud& cloud,
                   const CameraProjectorCalibration& calibration, const PatternSpec& spec,
                   const CameraNoise& noise, TriangulatorOptions::Use use) {
  if (static_cast<int>(cloud.points.size()) != cloud.width * cloud.height ||
      maps.modulation.size() != cv::Size(cloud.width, cloud.height))
    throw std::invalid_argument("point quality: cloud and maps must be organized, of one size");
  const bool have_u = !maps.up.empty(), have_v = !maps.vp.empty();
  using Use = TriangulatorOptions::Use;
  int first = -1, second = -1;  // 0 columns, 1 rows
  if (use == Use::kColumns) first = 0;
  if (use == Use::kRows) first = 1;
  if (use == Use::kBest) {
    const int preferred = std::abs(calibration.t.x()) >= std::abs(calibration.t.y()) ? 0 : 1;
    const bool have[2] = {have_u, have_v};
    if (have[preferred]) first = preferred;
    if (have[1 - preferred]) (first < 0 ? first : second) = 1 - preferred;
  }
  const bool have[2] = {have_u, have_v};
  if (first < 0 || !have[first])
    throw std::invalid_argument("point quality: the maps lack the projector axis to use");
  cv::Mat sigma_axis[2];
  for (int axis : {first, second})
    if (axis >= 0) sigma_axis[axis] = projectorCoordinateSigma(maps, spec, noise, axis == 0);
  const cv::Mat* coordinate[2] = {&maps.up, &maps.vp};
  const Eigen::Matrix3d& R = calibration.R;
  const Eigen::Vector3d& t = calibration.t;
  const PinholeModel& projector = calibration.projector;

  cv::Mat out(cloud.height, cloud.width, CV_32FC1, cv::Scalar(kNaN));
  for (int r = 0; r < cloud.height; ++r) {
    float* o = out.ptr<float>(r);
    for (int c = 0; c < cloud.width; ++c) {
      const PointXYZI& p = cloud.points[std::size_t(r) * cloud.width + c];
      if (!std::isfinite(p.z) || !(p.z > 0)) continue;
      int axis = first;
      if (!std::isfinite(coordinate[axis]->at<float>(r, c))) axis = second;
      if (axis < 0 || !std::isfinite(coordinate[axis]->at<float>(r, c))) continue;
      const float s_u = sigma_axis[axis].at<float>(r, c);
      if (!std::isfinite(s_u)) continue;
      // The point moved along its camera ray by +-h in z; projector coordinate
      // through the full projector model.
      const Eigen::Vector3d X(p.x, p.y, p.z);
      const Eigen::Vector3d ray = X / double(p.z);
      const double h = 1e-3 * p.z;
      const Eigen::Vector3d y_plus = R * (X + h * ray) + t, y_minus = R * (X - h * ray) + t;
      if (!(y_plus.z() > 0) || !(y_minus.z() > 0)) continue;
      const double du =
          (projector.project(y_plus)[axis] - projector.project(y_minus)[axis]) / (2 * h);
      if (!(std::abs(du) > 0)) continue;
      o[c] = static_cast<float>(s_u / std::abs(du));
    }
  }
  return out;
}

cv::Mat organizedNormals(const PointCloud& cloud, int step, float max_jump) {
  if (step < 1) throw std::invalid_argument("organizedNormals: step must be >= 1");
  if (static_cast<int>(cloud.points.size()) != cloud.width * cloud.height)
    throw std::invalid_argument("organizedNormals: the cloud is not organized");
  cv::Mat normals(cloud.height, cloud.width, CV_32FC3, cv::Scalar::all(kNaN));
  auto at = [&](int r, int c) -> Eigen::Vector3f {
    const PointXYZI& p = cloud.points[std::size_t(r) * cloud.width + c];
    return {p.x, p.y, p.z};
  };
  for (int r = step; r + step < cloud.height; ++r) {
    auto* o = normals.ptr<cv::Vec3f>(r);
    for (int c = step; c + step < cloud.width; ++c) {
      const Eigen::Vector3f p = at(r, c);
      if (!p.allFinite()) continue;
      const Eigen::Vector3f left = at(r, c - step), right = at(r, c + step);
      const Eigen::Vector3f up = at(r - step, c), down = at(r + step, c);
      if (!left.allFinite() || !right.allFinite() || !up.allFinite() || !down.allFinite())
        continue;
      if ((left - p).norm() > max_jump || (right - p).norm() > max_jump ||
          (up - p).norm() > max_jump || (down - p).norm() > max_jump)
        continue;
      Eigen::Vector3f n = (right - left).cross(down - up);
      const float length = n.norm();
      if (!(length > 0)) continue;
      n /= length;
      if (n.dot(p) > 0) n = -n;
      o[c] = cv::Vec3f(n.x(), n.y(), n.z());
    }
  }
  return normals;
}

}  // namespace sl::pipeline
