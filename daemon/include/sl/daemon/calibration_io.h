// Calibration files: the project's own YAML format, SLStudio's
// calibration.xml (OpenCV FileStorage) as an import. Read by the daemon, the
// offline tools and the calibration tool.
//
// The project's format (units mm and px; X_p = R * X_c + t):
//   format: sl-sensor-calibration/1
//   camera:    {width, height, fx, fy, cx, cy, distortion: [k1, k2, p1, p2, k3]}
//   projector: {width, height, fx, fy, cx, cy, distortion: [k1, k2, p1, p2, k3]}
//   projector_pose: {rotation: [9 numbers, row-major] | rotation_deg: [rx, ry, rz],
//                    translation_mm: [tx, ty, tz]}
//   errors: {camera_rms_px, projector_rms_px, stereo_rms_px}    # optional
//   board: {cols, rows, square_mm}                              # optional
//   date: "2026-11-23T10:00:00Z"                                # optional
//   source: "free text"                                         # optional
#pragma once

#include <optional>
#include <string>

#include "sl/pipeline/camera_model.h"

namespace sl::daemon {

struct CalibrationErrors {
  double camera_rms_px = 0;
  double projector_rms_px = 0;
  double stereo_rms_px = 0;
};

struct CalibrationBoard {
  int cols = 0;  // inner corners
  int rows = 0;
  double square_mm = 0;
};

struct CalibrationFile {
  pipeline::CameraProjectorCalibration calibration;
  std::optional<CalibrationErrors> errors;
  std::optional<CalibrationBoard> board;
  std::string date;
  std::string source;
};

// Reads a calibration: *.yaml / *.yml in the project's format, *.xml as
// SLStudio's calibration.xml (Kc, kc, Kp, kp, Rp, Tp, frameWidth/Height,
// screenResX/Y, cam/proj/stereo_error). Throws ConfigError naming the file
// and the key on any problem.
CalibrationFile loadCalibration(const std::string& path);

// Writes the project's format (atomically: temporary file + rename).
// Throws std::runtime_error naming the file on I/O failure.
void saveCalibration(const CalibrationFile& file, const std::string& path);

}  // namespace sl::daemon
