// Configuration of the Aravis cameras (`cameras:` for `sensor: hardware` and
// `sensor: fake_gige`) and of the fake GigE sensor: plain driver structs,
// filled from YAML by daemon/src/aravis_config.cpp.
#pragma once

#include <vector>

#include "sl/drivers/aravis_camera.h"
#include "sl/drivers/aravis_fake_camera.h"

namespace sl::daemon {

struct AravisSensorConfig {
  std::vector<drivers::AravisCameraConfig> cameras;  // camera 0 triangulates
  // sensor: fake_gige -- the simulated projector and trigger source drive an
  // in-process Aravis fake GigE Vision camera, which the cameras above open
  // over GVCP/GVSP like a real one.
  drivers::FakeGigeOptions fake;
};

}  // namespace sl::daemon
