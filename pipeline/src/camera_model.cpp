#include "sl/pipeline/camera_model.h"

#include <Eigen/Dense>

namespace sl::pipeline {

Eigen::Matrix3d PinholeModel::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

bool PinholeModel::hasDistortion() const {
  for (double d : distortion) {
    if (d != 0.0) return true;
  }
  return false;
}

namespace {

// Brown-Conrady: normalized undistorted -> normalized distorted.
Eigen::Vector2d distortNormalized(const std::array<double, 5>& d, const Eigen::Vector2d& xn) {
  const double x = xn.x(), y = xn.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  const double xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x);
  const double yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y;
  return {xd, yd};
}

}  // namespace

Eigen::Vector2d PinholeModel::normalizedToPixel(const Eigen::Vector2d& xn) const {
  const Eigen::Vector2d xd = hasDistortion() ? distortNormalized(distortion, xn) : xn;
  return {fx * xd.x() + cx, fy * xd.y() + cy};
}

Eigen::Vector2d PinholeModel::project(const Eigen::Vector3d& p) const {
  return normalizedToPixel({p.x() / p.z(), p.y() / p.z()});
}

Eigen::Vector2d PinholeModel::pixelToNormalized(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d xd{(pixel.x() - cx) / fx, (pixel.y() - cy) / fy};
  if (!hasDistortion()) return xd;
  // Fixed-point iteration x <- xd - (distort(x) - x), as OpenCV's undistortPoints
  // does; 20 iterations reach sub-micro-pixel residuals for moderate lenses.
  Eigen::Vector2d x = xd;
  for (int i = 0; i < 20; ++i) {
    const Eigen::Vector2d residual = distortNormalized(distortion, x) - xd;
    x -= residual;
    if (residual.squaredNorm() < 1e-24) break;
  }
  return x;
}

CameraProjectorCalibration inUnits(const CameraProjectorCalibration& calibration, double units_per_mm) {
  CameraProjectorCalibration scaled = calibration;
  scaled.t *= units_per_mm;
  return scaled;
}

Eigen::Isometry3d cameraToCamera(const CameraProjectorCalibration& from,
                                 const CameraProjectorCalibration& to) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = to.R.transpose() * from.R;
  pose.translation() = to.R.transpose() * (from.t - to.t);
  return pose;
}

}  // namespace sl::pipeline
