// Test support: the camera-projector rig of the pipeline tests and
// benchmarks: a distorted projector 175 mm left of the camera, the camera
// turned 12 deg towards it.
#pragma once

#include <Eigen/Geometry>
#include <numbers>

#include "sl/pipeline/camera_model.h"

namespace sl::test {

// The rig with `camera` (1440 x 1080 by default).
inline pipeline::CameraProjectorCalibration testRig(
    const pipeline::PinholeModel& camera = {1440, 1080, 2400, 2395, 722.4, 537.9,
                                            {-0.1, 0.05, 1e-3, -5e-4, 0.0}}) {
  pipeline::CameraProjectorCalibration c;
  c.camera = camera;
  c.projector = {1824, 1140, 2010, 1995, 905.3, 581.7, {0.06, -0.03, -6e-4, 4e-4, 0.0}};
  const Eigen::Matrix3d to_camera =
      Eigen::AngleAxisd(12.0 * std::numbers::pi / 180.0, Eigen::Vector3d::UnitY())
          .toRotationMatrix();
  c.R = to_camera.transpose();
  c.t = -c.R * Eigen::Vector3d(-175.0, 0.0, 0.0);
  return c;
}

}  // namespace sl::test
