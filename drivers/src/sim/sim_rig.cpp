#include "sl/drivers/sim_rig.h"

#include <Eigen/Geometry>
#include <numbers>

namespace sl::drivers {

pipeline::PinholeModel simCameraModel() {
  return {1440, 1080, 2400, 2400, 719.5, 539.5, {-0.08, 0.12, 0.0005, -0.0003, 0}};
}

pipeline::PinholeModel simProjectorModel() {
  return {1824, 1140, 2200, 2200, 911.5, 569.5, {0.02, -0.01, 0, 0, 0}};
}

pipeline::CameraProjectorCalibration simRig() {
  pipeline::CameraProjectorCalibration rig;
  rig.camera = simCameraModel();
  rig.projector = simProjectorModel();
  rig.R = Eigen::AngleAxisd(15.25 * std::numbers::pi / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  rig.t = -rig.R * Eigen::Vector3d(150, 0, 0);
  return rig;
}

}  // namespace sl::drivers
