// Calibration files: the project's own YAML format; SLStudio's
// calibration.xml and sl_sensor's camera + projector XML files (OpenCV
// FileStorage) as imports; an export to OpenCV FileStorage with SLStudio's
// keys. Read by the daemon, the offline tools and the calibration tool.
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

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "sl/pipeline/camera_model.h"

namespace sl::files {

// The largest camera or projector width or height any reader accepts
// (a 16384 x 16384 float map is 1 GiB); checked before anything is sized by it.
inline constexpr int kMaxImageSide = 16384;
// ... and width x height (a 4K projector is 8.3 MP, the paper's camera 1.6 MP;
// a 50 MP camera's cloud is 800 MB).
inline constexpr std::int64_t kMaxImagePixels = 50'000'000;

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

// Reads a calibration: *.yaml / *.yml in the project's format, *.xml (and
// *.yaml / *.yml starting with OpenCV's "%YAML:1.0" header) as SLStudio's
// calibration.xml (Kc, kc, Kp, kp, Rp, Tp, frameWidth/Height, screenResX/Y,
// cam/proj/stereo_error), which is also what exportOpenCvCalibration writes.
// An sl_sensor camera file is recognised and refused with a pointer to
// loadSlSensorCalibration (it lacks the projector). Throws ConfigError naming
// the file and the key on any problem.
CalibrationFile loadCalibration(const std::string& path);

// sl_sensor's calibration files (OpenCV FileStorage, as its calibrator
// writes them; the same keys SLStudio-derived code uses):
//   camera file:    intrinsic_mat (3x3), lens_distortion (5x1: k1 k2 p1 p2 k3),
//                   calibration_error, resolution_x, resolution_y,
//                   extrinsic_rot (3x3), extrinsic_trans (3x1), stereo_error
//   projector file: intrinsic_mat, lens_distortion, calibration_error,
//                   resolution_x, resolution_y
// extrinsic_rot / extrinsic_trans are the camera -> projector transform of
// cv::stereoCalibrate(camera points, projector points): X_p = R X_c + t, in
// the unit of the board squares given to sl_sensor's calibrator (mm in its
// shipped files and launch files; the file itself does not say).
// Throws ConfigError naming the file and the key.
CalibrationFile loadSlSensorCalibration(const std::string& camera_path,
                                        const std::string& projector_path);

// Which keys of a foreign OpenCV FileStorage calibration (YAML, XML or JSON,
// as cv::FileStorage writes them) hold what. A size is either a number
// (`width: 1824`, for files that do not store it) or the name of an
// integer key (`width: image_width`).
//
// As a YAML file (or inline, comma-separated dotted pairs:
// "camera.matrix=K1,camera.distortion=D1,...,projector.width=1824"):
//   camera:    {matrix: K1, distortion: D1, width: image_width, height: image_height}
//   projector: {matrix: K2, distortion: D2, width: 1824, height: 1140}
//   rotation: R            # 3x3 matrix, or a 3x1 / 1x3 Rodrigues vector
//   translation: T         # 3 elements
//   pose: camera_to_projector   # X_p = R X_c + T (cv::stereoCalibrate(camera,
//                               # projector)); or projector_to_camera: X_c = R X_p + T
//   translation_unit: mm   # mm (default), cm or m
// Distortion: OpenCV's order k1 k2 p1 p2 [k3 [k4 k5 k6 ...]]; 4 or 5
// elements, or more when all beyond k3 are 0 (the model has k1 k2 p1 p2 k3).
struct OpenCvCalibrationKeys {
  struct Device {
    std::string matrix, distortion;
    std::string width, height;  // a number or a key name
  };
  Device camera, projector;
  std::string rotation, translation;
  bool projector_to_camera = false;
  double translation_to_mm = 1.0;
  std::string origin;  // where the mapping came from, for messages
};

// Reads a key mapping from a YAML file, or, when `text` is not a file, from
// inline pairs. Throws ConfigError naming the file / pair and the key.
OpenCvCalibrationKeys parseOpenCvCalibrationKeys(const std::string& text);

// Reads an OpenCV FileStorage calibration through `keys`. Throws
// ConfigError naming the calibration file and the key (missing, wrong size,
// not a rotation, unsupported distortion terms, non-positive sizes).
CalibrationFile loadOpenCvCalibration(const std::string& path, const OpenCvCalibrationKeys& keys);

// Writes `file` as OpenCV FileStorage (format from the extension: .xml,
// .yaml / .yml, .json) with SLStudio's keys and conventions: Kc, kc, Kp, kp
// (CV_64F), Rp, Tp (X_p = Rp X_c + Tp, mm), frameWidth/Height,
// screenResX/Y, and cam_error, proj_error, stereo_error when known.
// Throws std::runtime_error naming the file on failure.
void exportOpenCvCalibration(const CalibrationFile& file, const std::string& path);

// A projector's intensity response (pipeline/projector_response.h) as a
// file, written by `sl_calibrate --projector-response` and read by
// `sl_process --projector-response`:
//   format: sl-sensor-projector-response/1
//   response: [R(0), ..., R(1)]    # at L = k / (n - 1), any affine scale
//   # or instead: gamma: 2.2       # R = L^gamma
//   source: "free text"            # optional
// Throws ConfigError naming the file and the key.
std::vector<float> loadProjectorResponse(const std::string& path);
void saveProjectorResponse(const std::vector<float>& response, const std::string& source,
                           const std::string& path);

// Writes the project's format (atomically: temporary file + rename).
// Throws std::runtime_error naming the file on I/O failure.
void saveCalibration(const CalibrationFile& file, const std::string& path);

}  // namespace sl::files
