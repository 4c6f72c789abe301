// Test support: the simulated rig of config/sim.yaml (projector 150 mm right
// of the camera, turned 15.25 deg so the optical axes cross at 550 mm).
#pragma once

#include <Eigen/Geometry>
#include <numbers>
#include <string>

#include "sl/drivers/sim.h"
#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/pattern.h"

namespace sl::test {

inline pipeline::CameraProjectorCalibration simDefaultRig() {
  pipeline::CameraProjectorCalibration rig;
  rig.camera = {1440, 1080, 2400, 2400, 719.5, 539.5, {-0.08, 0.12, 0.0005, -0.0003, 0}};
  rig.projector = {1824, 1140, 2200, 2200, 911.5, 569.5, {0.02, -0.01, 0, 0, 0}};
  rig.R = Eigen::AngleAxisd(15.25 * std::numbers::pi / 180, Eigen::Vector3d::UnitY())
              .toRotationMatrix();
  rig.t = -rig.R * Eigen::Vector3d(150, 0, 0);
  return rig;
}

// A simulator config on that rig with one 3+3 pattern (horizontal, the
// simulator's other defaults).
inline drivers::SimConfig simConfig33(const std::string& pattern_name,
                                      int fringes = pipeline::PhaseShift33Pattern{}.fringes) {
  drivers::SimConfig c;
  c.rig = simDefaultRig();
  pipeline::PhaseShift33Pattern p;
  p.name = pattern_name;
  p.fringes = fringes;
  c.patterns = {p};
  return c;
}

}  // namespace sl::test
