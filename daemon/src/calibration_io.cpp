#include "sl/daemon/calibration_io.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "calibration_yaml.h"

namespace sl::daemon {

pipeline::PinholeModel parsePinhole(const YamlMap& m) {
  pipeline::PinholeModel model;
  model.width = m.get<int>("width");
  model.height = m.get<int>("height");
  if (model.width <= 0) m.fail("width", "must be > 0");
  if (model.height <= 0) m.fail("height", "must be > 0");
  model.fx = positive(m, "fx", 0);
  model.fy = positive(m, "fy", 0);
  model.cx = m.get<double>("cx");
  model.cy = m.get<double>("cy");
  const auto d = m.get<std::vector<double>>("distortion", {0, 0, 0, 0, 0});
  if (d.size() != 5) m.fail("distortion", "expected 5 numbers (k1 k2 p1 p2 k3)");
  std::copy(d.begin(), d.end(), model.distortion.begin());
  m.done();
  return model;
}

// Projector pose relative to the camera: X_p = R * X_c + t.
namespace {

void parsePose(const YamlMap& m, pipeline::CameraProjectorCalibration& c) {
  const bool has_matrix = m.has("rotation");
  const bool has_angles = m.has("rotation_deg");
  if (has_matrix == has_angles)
    m.fail(has_matrix ? "rotation" : "rotation_deg",
           "give exactly one of 'rotation' (9 numbers, row-major) or 'rotation_deg' "
           "([rx, ry, rz], R = Rz * Ry * Rx)");
  if (has_matrix) {
    const auto r = m.get<std::vector<double>>("rotation");
    if (r.size() != 9) m.fail("rotation", "expected 9 numbers (row-major 3x3)");
    c.R = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(r.data());
    if ((c.R * c.R.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
        c.R.determinant() < 0)
      m.fail("rotation", "is not a rotation matrix");
  } else {
    const Eigen::Vector3d a = vec3(m, "rotation_deg") * std::numbers::pi / 180.0;
    c.R = (Eigen::AngleAxisd(a.z(), Eigen::Vector3d::UnitZ()) *
           Eigen::AngleAxisd(a.y(), Eigen::Vector3d::UnitY()) *
           Eigen::AngleAxisd(a.x(), Eigen::Vector3d::UnitX()))
              .toRotationMatrix();
  }
  c.t = vec3(m, "translation_mm");
  m.done();
}

}  // namespace

pipeline::CameraProjectorCalibration parseCalibrationKeys(const YamlMap& m) {
  pipeline::CameraProjectorCalibration c;
  c.camera = parsePinhole(m.map("camera"));
  c.projector = parsePinhole(m.map("projector"));
  parsePose(m.map("projector_pose"), c);
  return c;
}


namespace {

bool hasSuffix(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

CalibrationFile loadOwnYaml(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw ConfigError(path + ": cannot open calibration file");
  } catch (const YAML::Exception& e) {
    throw ConfigError(path + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
  const YamlMap m(root, path, "");
  const std::string format = m.get<std::string>("format", "sl-sensor-calibration/1");
  if (format != "sl-sensor-calibration/1")
    m.fail("format", "unsupported calibration format '" + format +
                         "' (this build reads sl-sensor-calibration/1)");
  CalibrationFile file;
  file.calibration = parseCalibrationKeys(m);
  if (m.has("errors")) {
    const YamlMap e = m.map("errors");
    file.errors = CalibrationErrors{nonNegative(e, "camera_rms_px", 0),
                                    nonNegative(e, "projector_rms_px", 0),
                                    nonNegative(e, "stereo_rms_px", 0)};
    e.done();
  }
  if (m.has("board")) {
    const YamlMap b = m.map("board");
    file.board = CalibrationBoard{b.get<int>("cols"), b.get<int>("rows"),
                                  positive(b, "square_mm", 0)};
    b.done();
  }
  file.date = m.get<std::string>("date", "");
  file.source = m.get<std::string>("source", "");
  m.done();
  return file;
}

// SLStudio's calibration.xml (OpenCV FileStorage).
CalibrationFile loadSlStudioXml(const std::string& path) {
  cv::FileStorage fs;
  try {
    fs.open(path, cv::FileStorage::READ);
  } catch (const cv::Exception& e) {
    throw ConfigError(path + ": cannot parse as OpenCV FileStorage XML: " + e.msg);
  }
  if (!fs.isOpened()) throw ConfigError(path + ": cannot open calibration file");
  auto matrix = [&](const char* key, int rows, int cols) {
    cv::Mat m;
    fs[key] >> m;
    if (m.empty())
      throw ConfigError(path + ": key '" + key +
                        "' missing (expected SLStudio's calibration.xml: Kc, kc, Kp, kp, Rp, Tp)");
    if (m.total() != std::size_t(rows) * cols)
      throw ConfigError(path + ": key '" + key + "' must have " + std::to_string(rows * cols) +
                        " elements");
    cv::Mat d;
    m.reshape(1, rows).convertTo(d, CV_64F);
    return d;
  };
  auto integer = [&](const char* key) {
    const cv::FileNode node = fs[key];
    if (node.empty() || !node.isInt()) throw ConfigError(path + ": key '" + key + "' missing");
    return static_cast<int>(node);
  };
  auto pinhole = [&](const char* K_key, const char* k_key, int width, int height) {
    const cv::Mat K = matrix(K_key, 3, 3), k = matrix(k_key, 5, 1);
    pipeline::PinholeModel model;
    model.width = width;
    model.height = height;
    model.fx = K.at<double>(0, 0);
    model.fy = K.at<double>(1, 1);
    model.cx = K.at<double>(0, 2);
    model.cy = K.at<double>(1, 2);
    for (int i = 0; i < 5; ++i) model.distortion[i] = k.at<double>(i, 0);
    return model;
  };
  CalibrationFile file;
  auto& c = file.calibration;
  c.camera = pinhole("Kc", "kc", integer("frameWidth"), integer("frameHeight"));
  c.projector = pinhole("Kp", "kp", integer("screenResX"), integer("screenResY"));
  const cv::Mat R = matrix("Rp", 3, 3), t = matrix("Tp", 3, 1);
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) c.R(r, col) = R.at<double>(r, col);
    c.t(r) = t.at<double>(r, 0);
  }
  if (std::abs(c.R.determinant() - 1.0) > 1e-4)
    throw ConfigError(path + ": key 'Rp' is not a rotation matrix");
  if (!fs["cam_error"].empty())
    file.errors = CalibrationErrors{static_cast<double>(fs["cam_error"]),
                                    static_cast<double>(fs["proj_error"]),
                                    static_cast<double>(fs["stereo_error"])};
  file.source = "SLStudio calibration.xml";
  return file;
}

void writePinhole(std::ostream& out, const char* name, const pipeline::PinholeModel& m) {
  out << name << ":\n"
      << "  width: " << m.width << "\n  height: " << m.height << "\n"
      << "  fx: " << m.fx << "\n  fy: " << m.fy << "\n  cx: " << m.cx << "\n  cy: " << m.cy
      << "\n  distortion: [" << m.distortion[0] << ", " << m.distortion[1] << ", "
      << m.distortion[2] << ", " << m.distortion[3] << ", " << m.distortion[4] << "]\n";
}

}  // namespace

CalibrationFile loadCalibration(const std::string& path) {
  if (!std::filesystem::exists(path)) throw ConfigError(path + ": calibration file not found");
  if (hasSuffix(path, ".xml")) return loadSlStudioXml(path);
  if (hasSuffix(path, ".yaml") || hasSuffix(path, ".yml")) return loadOwnYaml(path);
  throw ConfigError(path + ": unknown calibration format (expected .yaml/.yml in the project's "
                    "format or SLStudio's calibration .xml)");
}

void saveCalibration(const CalibrationFile& file, const std::string& path) {
  std::ostringstream out;
  out.precision(17);
  out << "# sl-sensor calibration of one camera-projector pair (mm, px).\n"
      << "# Projector pose: X_projector = R * X_camera + t.\n"
      << "format: sl-sensor-calibration/1\n";
  writePinhole(out, "camera", file.calibration.camera);
  writePinhole(out, "projector", file.calibration.projector);
  const auto& R = file.calibration.R;
  const auto& t = file.calibration.t;
  out << "projector_pose:\n  rotation: [";
  for (int i = 0; i < 9; ++i) out << (i ? ", " : "") << R(i / 3, i % 3);
  out << "]\n  translation_mm: [" << t.x() << ", " << t.y() << ", " << t.z() << "]\n";
  if (file.errors)
    out << "errors:\n  camera_rms_px: " << file.errors->camera_rms_px
        << "\n  projector_rms_px: " << file.errors->projector_rms_px
        << "\n  stereo_rms_px: " << file.errors->stereo_rms_px << "\n";
  if (file.board)
    out << "board:\n  cols: " << file.board->cols << "\n  rows: " << file.board->rows
        << "\n  square_mm: " << file.board->square_mm << "\n";
  if (!file.date.empty()) out << "date: " << YAML::Node(file.date) << "\n";
  if (!file.source.empty()) out << "source: " << YAML::Node(file.source) << "\n";
  const std::string temporary = path + ".part";
  {
    std::ofstream f(temporary, std::ios::trunc);
    if (!f) throw std::runtime_error(temporary + ": cannot open for writing");
    f << out.str();
    if (!f.flush()) throw std::runtime_error(temporary + ": write failed");
  }
  std::error_code error;
  std::filesystem::rename(temporary, path, error);
  if (error) throw std::runtime_error(path + ": cannot rename from .part: " + error.message());
}

}  // namespace sl::daemon
