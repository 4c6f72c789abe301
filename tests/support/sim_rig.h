// Test support: simulators on the rig of config/sim.yaml (drivers::simRig()).
#pragma once

#include <string>

#include "sl/drivers/sim.h"
#include "sl/drivers/sim_rig.h"
#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/pattern.h"

namespace sl::test {

inline pipeline::CameraProjectorCalibration simDefaultRig() { return drivers::simRig(); }

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

// The scene the codec and processing tests render on that rig: a plane
// 600 mm away tilted by (0.1, 0.2) and a sphere of radius 60 mm in front of
// it (albedo 0.8 and 0.7), the simulator's default noise and optics, no
// pattern yet.
inline drivers::SimConfig simPlaneAndSphere() {
  drivers::SimConfig c;
  c.rig = simDefaultRig();
  drivers::SimPlane plane;
  plane.point = {0, 0, 600};
  plane.normal = {0.1, 0.2, -1};
  plane.albedo = 0.8;
  c.scene.planes = {plane};
  drivers::SimSphere sphere;
  sphere.center = {40, -20, 520};
  sphere.radius = 60;
  sphere.albedo = 0.7;
  c.scene.spheres = {sphere};
  return c;
}

}  // namespace sl::test
