// The simulated sensor's rig, defined once: the geometry of config/sim.yaml
// (whose calibration block states it in YAML; test_config checks that the
// two agree) that tests, benchmarks and sl_eval build simulators on.
#pragma once

#include "sl/pipeline/camera_model.h"

namespace sl::drivers {

// 1440 x 1080 camera, f = 2400 px, with a mildly distorting lens.
pipeline::PinholeModel simCameraModel();
// 1824 x 1140 projector (the LightCrafter 4500's addressed resolution),
// f = 2200 px.
pipeline::PinholeModel simProjectorModel();
// The camera and the projector 150 mm to its right (+x), turned 15.25 deg
// about y so that the optical axes cross at about 550 mm. Millimetres,
// camera optical frame (R, t map camera to projector coordinates).
pipeline::CameraProjectorCalibration simRig();

}  // namespace sl::drivers
