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

}  // namespace sl::test
