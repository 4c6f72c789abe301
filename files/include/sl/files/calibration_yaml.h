// Parsing of the calibration blocks shared by config files and calibration
// files (private to daemon/).
#pragma once

#include "sl/pipeline/camera_model.h"
#include "yaml_reader.h"

namespace sl::files {

pipeline::PinholeModel parsePinhole(const YamlMap& m);
// camera, projector and projector_pose keys of `m` (other keys untouched).
pipeline::CameraProjectorCalibration parseCalibrationKeys(const YamlMap& m);

}  // namespace sl::files
