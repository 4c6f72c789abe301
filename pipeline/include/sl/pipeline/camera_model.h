// Pinhole + Brown distortion model shared by cameras and the projector (an
// inverse camera), and the calibration of one camera-projector pair.
#pragma once

#include <array>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace sl::pipeline {

// Pinhole intrinsics with Brown-Conrady distortion (k1 k2 p1 p2 k3, the order
// OpenCV uses). Pixel coordinates have the origin at the centre of the
// top-left pixel.
struct PinholeModel {
  int width = 0;   // px
  int height = 0;  // px
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::array<double, 5> distortion{0, 0, 0, 0, 0};  // k1 k2 p1 p2 k3

  Eigen::Matrix3d K() const;
  bool hasDistortion() const;

  // Normalized undistorted coordinates (x/z, y/z) -> distorted pixel.
  Eigen::Vector2d normalizedToPixel(const Eigen::Vector2d& xn) const;
  // Point in this device's frame (mm) -> distorted pixel. z must be > 0.
  Eigen::Vector2d project(const Eigen::Vector3d& p) const;
  // Distorted pixel -> normalized undistorted coordinates, by fixed-point
  // iteration (converges to < 1e-6 px for the distortion of real lenses).
  Eigen::Vector2d pixelToNormalized(const Eigen::Vector2d& pixel) const;
};

// One camera calibrated against the projector. The camera's optical frame is
// the world frame; a point X_c in it maps to the projector frame by
// X_p = R * X_c + t (mm).
struct CameraProjectorCalibration {
  PinholeModel camera;
  PinholeModel projector;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();  // mm
};

// The same calibration with its lengths (t) in another unit: `units_per_mm`
// of them per millimetre (1e-3: metres). Intrinsics and R have no length, so
// a Triangulator built from it (with its depth limits scaled alike) gives
// clouds in that unit directly, without a conversion pass over the points.
CameraProjectorCalibration inUnits(const CameraProjectorCalibration& calibration, double units_per_mm);

// Two cameras calibrated against the same projector: the pose taking a point
// of `from`'s frame into `to`'s frame, X_to = pose * X_from (both map to the
// projector: R_from X_from + t_from = R_to X_to + t_to).
Eigen::Isometry3d cameraToCamera(const CameraProjectorCalibration& from,
                                 const CameraProjectorCalibration& to);

}  // namespace sl::pipeline
