#include "sl/files/calibration_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <new>
#include <numbers>
#include <optional>
#include <sstream>
#include <type_traits>
#include <utility>


#include <Eigen/Geometry>
#include <expat.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "sl/files/calibration_yaml.h"
#include "sl/files/input_file.h"
#include "sl/pipeline/projector_response.h"

namespace sl::files {

pipeline::PinholeModel parsePinhole(const YamlMap& m) {
  pipeline::PinholeModel model;
  model.width = m.get<int>("width");
  model.height = m.get<int>("height");
  // Bounded before anything is sized by them (maps, LUTs, images).
  if (model.width <= 0 || model.width > kMaxImageSide)
    m.fail("width", "must be 1.." + std::to_string(kMaxImageSide));
  if (model.height <= 0 || model.height > kMaxImageSide)
    m.fail("height", "must be 1.." + std::to_string(kMaxImageSide));
  if (std::int64_t{model.width} * model.height > kMaxImagePixels)
    m.fail("height", std::to_string(model.width) + " x " + std::to_string(model.height) +
                         " is more than " + std::to_string(kMaxImagePixels / 1'000'000) +
                         " megapixels");
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

// `text`: the file's contents, read by readInputFile (one YAML document,
// aliases bounded by parseInputYaml).
CalibrationFile loadOwnYaml(const std::string& path, const std::string& text) {
  const YAML::Node root = parseInputYaml(text, path);
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

// Throws ConfigError "<path>:<line>: malformed XML: <expat's reason>" unless
// `text` is one well-formed XML document. Expat loads no external entities.
void checkWellFormedXml(const std::string& path, const std::string& text) {
  const std::unique_ptr<std::remove_pointer_t<XML_Parser>, decltype(&XML_ParserFree)> parser(
      XML_ParserCreate(nullptr), &XML_ParserFree);
  if (!parser) throw std::bad_alloc();
  if (text.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw ConfigError(path + ": too large for an XML calibration file");
  if (XML_Parse(parser.get(), text.data(), static_cast<int>(text.size()), XML_TRUE) ==
      XML_STATUS_OK)
    return;
  throw ConfigError(path + ":" + std::to_string(XML_GetCurrentLineNumber(parser.get())) +
                    ": malformed XML: " + XML_ErrorString(XML_GetErrorCode(parser.get())));
}

// OpenCV 4.6's XML parser dereferences null on malformed XML: a NUL byte
// inside a tag, a truncated declaration (`<?xml versiveorsn=`), both found
// by fuzz_calibration. Text files never hold a NUL byte, and XML (what
// starts with '<') reaches OpenCV only once expat found it well-formed.
void checkStorageText(const std::string& path, const std::string& text) {
  if (text.find('\0') != std::string::npos)
    throw ConfigError(path + ": contains a NUL byte, not a text calibration file");
  const std::size_t first = text.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && text[first] == '<') checkWellFormedXml(path, text);
}

// Opens `text` (the contents of `path`, read by readInputFile) in OpenCV
// from memory: OpenCV never opens the path itself (no FIFO, device or file
// swapped after the checks reaches it).
void openStorage(cv::FileStorage& fs, const std::string& path, const std::string& text) {
  checkStorageText(path, text);
  fs.open(text, cv::FileStorage::READ | cv::FileStorage::MEMORY);
}

// An OpenCV FileStorage file opened for reading, with typed accessors that
// throw ConfigError naming the file and the key. `expected` describes the
// file's format in the message for a missing key.
class StorageReader {
 public:
  StorageReader(const std::string& path, std::string expected)
      : StorageReader(path, readInputFile(path, InputKind::kCalibration), std::move(expected)) {}
  StorageReader(const std::string& path, const std::string& text, std::string expected)
      : path_(path), expected_(std::move(expected)) {
    try {
      openStorage(fs_, path, text);
    } catch (const std::length_error&) {
      throw ConfigError(path + ": cannot parse as OpenCV FileStorage");
    } catch (const cv::Exception& e) {
      throw ConfigError(path + ": cannot parse as OpenCV FileStorage: " + e.msg);
    }
    if (!fs_.isOpened()) throw ConfigError(path + ": cannot open calibration file");
  }

  bool has(const char* key) const { return !fs_[key].empty(); }

  cv::Mat matrix(const char* key, int rows, int cols) const {
    cv::Mat m;
    // OpenCV allocates the declared rows x cols before reading the data: a
    // small file declaring a huge matrix took > 2 GB (found by
    // fuzz_calibration), so the declared size is checked first.
    const cv::FileNode node = fs_[key];
    if (node.isMap()) {
      const cv::FileNode r = node["rows"], c = node["cols"];
      const bool declared_ok =
          r.isInt() && c.isInt() &&
          std::int64_t{static_cast<int>(r)} * static_cast<int>(c) == std::int64_t{rows} * cols;
      if (!declared_ok)
        throw ConfigError(path_ + ": key '" + key + "' must have " + std::to_string(rows * cols) +
                          " elements");
    }
    try {
      node >> m;
    } catch (const cv::Exception& e) {
      throw ConfigError(path_ + ": key '" + key + "' is not a matrix: " + e.msg);
    }
    if (m.empty()) throw ConfigError(path_ + ": key '" + key + "' missing (expected " + expected_ + ")");
    if (m.total() != std::size_t(rows) * cols || m.channels() != 1)
      throw ConfigError(path_ + ": key '" + key + "' must have " + std::to_string(rows * cols) +
                        " elements");
    cv::Mat d;
    m.reshape(1, rows).convertTo(d, CV_64F);
    if (!cv::checkRange(d)) throw ConfigError(path_ + ": key '" + key + "' is not finite");
    return d;
  }

  int integer(const char* key) const {
    const cv::FileNode node = fs_[key];
    if (node.empty() || !node.isInt())
      throw ConfigError(path_ + ": key '" + key + "' missing or not an integer (expected " +
                        expected_ + ")");
    const int value = static_cast<int>(node);
    if (value <= 0 || value > kMaxImageSide)  // integer() reads image sizes only
      throw ConfigError(path_ + ": key '" + key + "' must be 1.." + std::to_string(kMaxImageSide));
    return value;
  }

  std::optional<double> real(const char* key) const {
    const cv::FileNode node = fs_[key];
    if (node.empty() || !(node.isReal() || node.isInt())) return std::nullopt;
    return static_cast<double>(node);
  }

  pipeline::PinholeModel pinhole(const char* K_key, const char* k_key, int width,
                                 int height) const {
    if (std::int64_t{width} * height > kMaxImagePixels)
      throw ConfigError(path_ + ": " + std::to_string(width) + " x " + std::to_string(height) +
                        " is more than " + std::to_string(kMaxImagePixels / 1'000'000) +
                        " megapixels");
    const cv::Mat K = matrix(K_key, 3, 3), k = matrix(k_key, 5, 1);
    pipeline::PinholeModel model;
    model.width = width;
    model.height = height;
    model.fx = K.at<double>(0, 0);
    model.fy = K.at<double>(1, 1);
    model.cx = K.at<double>(0, 2);
    model.cy = K.at<double>(1, 2);
    if (!(model.fx > 0 && model.fy > 0))
      throw ConfigError(path_ + ": key '" + K_key + "' must have positive focal lengths");
    for (int i = 0; i < 5; ++i) model.distortion[i] = k.at<double>(i, 0);
    return model;
  }

  // R (3x3 rotation) and t (3x1) into c.
  void pose(const char* R_key, const char* t_key, pipeline::CameraProjectorCalibration& c) const {
    const cv::Mat R = matrix(R_key, 3, 3), t = matrix(t_key, 3, 1);
    for (int r = 0; r < 3; ++r) {
      for (int col = 0; col < 3; ++col) c.R(r, col) = R.at<double>(r, col);
      c.t(r) = t.at<double>(r, 0);
    }
    // Files store float: orthonormal to about 1e-7 per element.
    if ((c.R * c.R.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-4 ||
        c.R.determinant() < 0)
      throw ConfigError(path_ + ": key '" + R_key + "' is not a rotation matrix");
  }

 private:
  cv::FileStorage fs_;
  std::string path_;
  std::string expected_;
};

constexpr const char* kSlStudioKeys = "SLStudio's calibration.xml: Kc, kc, Kp, kp, Rp, Tp";

// SLStudio's calibration.xml (OpenCV FileStorage); `text`: its contents.
CalibrationFile loadSlStudioXml(const std::string& path, const std::string& text) {
  const StorageReader fs(path, text, kSlStudioKeys);
  if (!fs.has("Kc") && fs.has("intrinsic_mat"))
    throw ConfigError(path + ": this is an sl_sensor " +
                      (fs.has("extrinsic_rot") ? "camera" : "projector") +
                      " file; it needs its partner (camera + projector): convert both with "
                      "'sl_calibrate --import-sl-sensor CAMERA.xml PROJECTOR.xml --out FILE.yaml'");
  CalibrationFile file;
  auto& c = file.calibration;
  c.camera = fs.pinhole("Kc", "kc", fs.integer("frameWidth"), fs.integer("frameHeight"));
  c.projector = fs.pinhole("Kp", "kp", fs.integer("screenResX"), fs.integer("screenResY"));
  fs.pose("Rp", "Tp", c);
  if (fs.has("cam_error"))
    file.errors = CalibrationErrors{fs.real("cam_error").value_or(0),
                                    fs.real("proj_error").value_or(0),
                                    fs.real("stereo_error").value_or(0)};
  file.source = "SLStudio calibration.xml";
  return file;
}

bool startsWithOpenCvYamlHeader(const std::string& text) { return text.rfind("%YAML", 0) == 0; }

void writePinhole(std::ostream& out, const char* name, const pipeline::PinholeModel& m) {
  out << name << ":\n"
      << "  width: " << m.width << "\n  height: " << m.height << "\n"
      << "  fx: " << m.fx << "\n  fy: " << m.fy << "\n  cx: " << m.cx << "\n  cy: " << m.cy
      << "\n  distortion: [" << m.distortion[0] << ", " << m.distortion[1] << ", "
      << m.distortion[2] << ", " << m.distortion[3] << ", " << m.distortion[4] << "]\n";
}

}  // namespace

CalibrationFile loadCalibration(const std::string& path) {
  std::error_code error;
  const auto status = std::filesystem::status(path, error);
  if (error || !std::filesystem::exists(status))
    throw ConfigError(path + ": calibration file not found");
  const bool xml = hasSuffix(path, ".xml");
  if (!xml && !hasSuffix(path, ".yaml") && !hasSuffix(path, ".yml"))
    throw ConfigError(path + ": unknown calibration format (expected .yaml/.yml in the project's "
                      "format or SLStudio's calibration .xml)");
  // Regular files only, 16 MiB at most (real ones are a few KB), read once:
  // the parsers below see this text, never the path.
  const std::string text = readInputFile(path, InputKind::kCalibration);
  if (xml) return loadSlStudioXml(path, text);
  return startsWithOpenCvYamlHeader(text) ? loadSlStudioXml(path, text) : loadOwnYaml(path, text);
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


CalibrationFile loadSlSensorCalibration(const std::string& camera_path,
                                        const std::string& projector_path) {
  for (const std::string& p : {camera_path, projector_path})
    if (!std::filesystem::exists(p)) throw ConfigError(p + ": calibration file not found");
  const StorageReader camera(camera_path,
                             "sl_sensor camera file: intrinsic_mat, lens_distortion, "
                             "resolution_x/y, extrinsic_rot, extrinsic_trans");
  const StorageReader projector(projector_path,
                                "sl_sensor projector file: intrinsic_mat, lens_distortion, "
                                "resolution_x/y");
  CalibrationFile file;
  auto& c = file.calibration;
  c.camera = camera.pinhole("intrinsic_mat", "lens_distortion", camera.integer("resolution_x"),
                            camera.integer("resolution_y"));
  c.projector = projector.pinhole("intrinsic_mat", "lens_distortion",
                                  projector.integer("resolution_x"),
                                  projector.integer("resolution_y"));
  if (projector.has("extrinsic_rot") && !camera.has("extrinsic_rot"))
    throw ConfigError(camera_path + ": has no 'extrinsic_rot' but " + projector_path +
                      " has: are the camera and projector files swapped?");
  camera.pose("extrinsic_rot", "extrinsic_trans", c);
  const auto camera_error = camera.real("calibration_error");
  const auto projector_error = projector.real("calibration_error");
  const auto stereo_error = camera.real("stereo_error");
  if (camera_error || projector_error || stereo_error)
    file.errors = CalibrationErrors{camera_error.value_or(0), projector_error.value_or(0),
                                    stereo_error.value_or(0)};
  file.source = "sl_sensor " + std::filesystem::path(camera_path).filename().string() + " + " +
                std::filesystem::path(projector_path).filename().string();
  return file;
}

namespace {

double translationScale(const std::string& unit, const std::string& where) {
  if (unit == "mm") return 1.0;
  if (unit == "cm") return 10.0;
  if (unit == "m") return 1000.0;
  throw ConfigError(where + ": translation_unit must be mm, cm or m, not '" + unit + "'");
}

void setPose(const std::string& value, const std::string& where, OpenCvCalibrationKeys& k) {
  if (value == "camera_to_projector") k.projector_to_camera = false;
  else if (value == "projector_to_camera") k.projector_to_camera = true;
  else
    throw ConfigError(where + ": pose must be camera_to_projector or projector_to_camera, not '" +
                      value + "'");
}

void checkComplete(const OpenCvCalibrationKeys& k) {
  const std::pair<const char*, const std::string*> required[] = {
      {"camera.matrix", &k.camera.matrix},         {"camera.distortion", &k.camera.distortion},
      {"camera.width", &k.camera.width},           {"camera.height", &k.camera.height},
      {"projector.matrix", &k.projector.matrix},   {"projector.distortion", &k.projector.distortion},
      {"projector.width", &k.projector.width},     {"projector.height", &k.projector.height},
      {"rotation", &k.rotation},                   {"translation", &k.translation}};
  for (const auto& [name, value] : required)
    if (value->empty())
      throw ConfigError(k.origin + ": key mapping lacks '" + name +
                        "' (needed: camera/projector matrix, distortion, width, height; rotation, "
                        "translation)");
}

}  // namespace

OpenCvCalibrationKeys parseOpenCvCalibrationKeys(const std::string& text) {
  OpenCvCalibrationKeys k;
  std::error_code no_file;
  if (text.find('=') == std::string::npos || std::filesystem::is_regular_file(text, no_file)) {
    k.origin = text;
    if (!std::filesystem::is_regular_file(text, no_file))
      throw ConfigError(text + ": neither a key-mapping file nor inline pairs "
                               "(camera.matrix=K1,...)");
    const YAML::Node root = loadInputYaml(text, InputKind::kCalibration);
    const YamlMap m(root, text, "");
    for (auto [name, device] : {std::pair{"camera", &k.camera}, std::pair{"projector", &k.projector}}) {
      const YamlMap d = m.map(name);
      device->matrix = d.get<std::string>("matrix");
      device->distortion = d.get<std::string>("distortion");
      device->width = d.get<std::string>("width");
      device->height = d.get<std::string>("height");
      d.done();
    }
    k.rotation = m.get<std::string>("rotation");
    k.translation = m.get<std::string>("translation");
    setPose(m.get<std::string>("pose", "camera_to_projector"), text + ": pose", k);
    k.translation_to_mm =
        translationScale(m.get<std::string>("translation_unit", "mm"), text + ": translation_unit");
    m.done();
  } else {
    k.origin = "key mapping '" + text + "'";
    std::stringstream pairs(text);
    for (std::string pair; std::getline(pairs, pair, ',');) {
      const auto eq = pair.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == pair.size())
        throw ConfigError(k.origin + ": '" + pair + "' is not name=key");
      const std::string name = pair.substr(0, eq), value = pair.substr(eq + 1);
      std::string* slot = nullptr;
      if (name == "camera.matrix") slot = &k.camera.matrix;
      else if (name == "camera.distortion") slot = &k.camera.distortion;
      else if (name == "camera.width") slot = &k.camera.width;
      else if (name == "camera.height") slot = &k.camera.height;
      else if (name == "projector.matrix") slot = &k.projector.matrix;
      else if (name == "projector.distortion") slot = &k.projector.distortion;
      else if (name == "projector.width") slot = &k.projector.width;
      else if (name == "projector.height") slot = &k.projector.height;
      else if (name == "rotation") slot = &k.rotation;
      else if (name == "translation") slot = &k.translation;
      else if (name == "pose") setPose(value, k.origin, k);
      else if (name == "translation_unit") k.translation_to_mm = translationScale(value, k.origin);
      else
        throw ConfigError(k.origin + ": unknown name '" + name +
                          "' (camera./projector.matrix, distortion, width, height; rotation, "
                          "translation, pose, translation_unit)");
      if (slot) {
        if (!slot->empty()) throw ConfigError(k.origin + ": '" + name + "' given twice");
        *slot = value;
      }
    }
  }
  checkComplete(k);
  return k;
}

CalibrationFile loadOpenCvCalibration(const std::string& path, const OpenCvCalibrationKeys& keys) {
  if (!std::filesystem::exists(path)) throw ConfigError(path + ": calibration file not found");
  const std::string expected = "the keys of " + keys.origin;
  const std::string text = readInputFile(path, InputKind::kCalibration);
  cv::FileStorage fs;
  try {
    openStorage(fs, path, text);
  } catch (const cv::Exception& e) {
    throw ConfigError(path + ": cannot parse as OpenCV FileStorage: " + e.msg);
  }
  if (!fs.isOpened()) throw ConfigError(path + ": cannot open as OpenCV FileStorage");
  auto matrix = [&](const std::string& key) {
    const cv::FileNode node = fs[key];
    if (node.empty())
      throw ConfigError(path + ": key '" + key + "' missing (named by " + keys.origin + ")");
    cv::Mat m;
    try {
      node >> m;
    } catch (const cv::Exception& e) {
      throw ConfigError(path + ": key '" + key + "' is not a matrix: " + e.msg);
    }
    if (m.empty() || m.channels() != 1)
      throw ConfigError(path + ": key '" + key + "' is not a single-channel matrix");
    cv::Mat d;
    m.convertTo(d, CV_64F);
    if (!cv::checkRange(d)) throw ConfigError(path + ": key '" + key + "' is not finite");
    return d;
  };
  auto size = [&](const std::string& value, const char* what) {
    if (!value.empty() && std::all_of(value.begin(), value.end(), ::isdigit)) {
      const int v = std::stoi(value);
      if (v <= 0) throw ConfigError(keys.origin + ": " + what + " must be > 0");
      return v;
    }
    const cv::FileNode node = fs[value];
    if (node.empty() || !(node.isInt() || node.isReal()))
      throw ConfigError(path + ": key '" + value + "' (" + what +
                        ") missing or not a number; give the size as a number in " + keys.origin +
                        " when the file does not store it");
    const double v = static_cast<double>(node);
    if (!(v > 0) || v != std::floor(v))
      throw ConfigError(path + ": key '" + value + "' (" + what + ") must be a positive integer");
    return static_cast<int>(v);
  };
  auto pinhole = [&](const OpenCvCalibrationKeys::Device& d, const char* device) {
    pipeline::PinholeModel model;
    model.width = size(d.width, (std::string(device) + " width").c_str());
    model.height = size(d.height, (std::string(device) + " height").c_str());
    const cv::Mat K = matrix(d.matrix);
    if (K.total() != 9)
      throw ConfigError(path + ": key '" + d.matrix + "' (" + device + " matrix) must be 3x3, has " +
                        std::to_string(K.total()) + " elements");
    const cv::Mat K3 = K.reshape(1, 3);
    model.fx = K3.at<double>(0, 0);
    model.fy = K3.at<double>(1, 1);
    model.cx = K3.at<double>(0, 2);
    model.cy = K3.at<double>(1, 2);
    if (!(model.fx > 0 && model.fy > 0) || K3.at<double>(2, 2) != 1.0 ||
        K3.at<double>(1, 0) != 0 || K3.at<double>(2, 0) != 0 || K3.at<double>(2, 1) != 0)
      throw ConfigError(path + ": key '" + d.matrix + "' (" + device +
                        " matrix) is not [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0");
    if (std::abs(K3.at<double>(0, 1)) > 1e-9 * model.fx)
      throw ConfigError(path + ": key '" + d.matrix + "' (" + device +
                        " matrix) has a skew term, which the model does not have");
    const cv::Mat k = matrix(d.distortion);
    const std::size_t n = k.total();
    if (n != 4 && n != 5 && n != 8 && n != 12 && n != 14)
      throw ConfigError(path + ": key '" + d.distortion + "' (" + device +
                        " distortion) has " + std::to_string(n) +
                        " elements; expected 4, 5, 8, 12 or 14 (OpenCV's order)");
    const cv::Mat flat = k.reshape(1, 1);
    for (std::size_t i = 5; i < n; ++i)
      if (flat.at<double>(0, static_cast<int>(i)) != 0.0)
        throw ConfigError(path + ": key '" + d.distortion + "' (" + device + " distortion) term " +
                          std::to_string(i) +
                          " is not 0: the model has k1 k2 p1 p2 k3 only (rational or thin-prism "
                          "terms are not supported)");
    for (std::size_t i = 0; i < 5; ++i)
      model.distortion[i] = i < n ? flat.at<double>(0, static_cast<int>(i)) : 0.0;
    return model;
  };
  CalibrationFile file;
  auto& c = file.calibration;
  c.camera = pinhole(keys.camera, "camera");
  c.projector = pinhole(keys.projector, "projector");
  const cv::Mat r = matrix(keys.rotation);
  cv::Mat R;
  if (r.total() == 9) R = r.reshape(1, 3);
  else if (r.total() == 3) cv::Rodrigues(r.reshape(1, 3), R);
  else
    throw ConfigError(path + ": key '" + keys.rotation +
                      "' (rotation) must be a 3x3 matrix or a Rodrigues vector of 3");
  const cv::Mat t = matrix(keys.translation);
  if (t.total() != 3)
    throw ConfigError(path + ": key '" + keys.translation + "' (translation) must have 3 elements");
  Eigen::Matrix3d Re;
  Eigen::Vector3d te;
  const cv::Mat t3 = t.reshape(1, 3);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) Re(i, j) = R.at<double>(i, j);
    te(i) = t3.at<double>(i, 0) * keys.translation_to_mm;
  }
  if ((Re * Re.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-4 || Re.determinant() < 0)
    throw ConfigError(path + ": key '" + keys.rotation + "' (rotation) is not a rotation matrix");
  if (keys.projector_to_camera) {
    // X_c = R X_p + T  <=>  X_p = R^T X_c - R^T T.
    c.R = Re.transpose();
    c.t = -Re.transpose() * te;
  } else {
    c.R = Re;
    c.t = te;
  }
  file.source = "OpenCV FileStorage " + std::filesystem::path(path).filename().string() +
                " through " + keys.origin;
  return file;
}

std::vector<float> loadProjectorResponse(const std::string& path) {
  const YAML::Node root = loadInputYaml(path, InputKind::kProjectorResponse);
  const YamlMap m(root, path, "");
  const std::string format = m.get<std::string>("format", "sl-sensor-projector-response/1");
  if (format != "sl-sensor-projector-response/1")
    m.fail("format", "unsupported format '" + format + "' (this build reads "
                     "sl-sensor-projector-response/1)");
  if (m.has("gamma") == m.has("response"))
    m.fail("response", "give exactly one of 'response' (samples of R at L = 0 .. 1) or 'gamma'");
  std::vector<float> response;
  try {
    if (m.has("gamma")) {
      response = pipeline::gammaResponse(positive(m, "gamma", 1.0));
    } else {
      for (double v : m.get<std::vector<double>>("response")) response.push_back(static_cast<float>(v));
      pipeline::validateProjectorResponse(response);
    }
  } catch (const std::invalid_argument& e) {
    m.fail(m.has("gamma") ? "gamma" : "response", e.what());
  }
  m.get<std::string>("source", "");
  m.done();
  return response;
}

void saveProjectorResponse(const std::vector<float>& response, const std::string& source,
                           const std::string& path) {
  std::ostringstream out;
  out.precision(7);
  out << "# Projector intensity response R(L) at L = k / (n - 1) (sl_calibrate).\n"
      << "format: sl-sensor-projector-response/1\nresponse: [";
  for (std::size_t k = 0; k < response.size(); ++k) out << (k ? ", " : "") << response[k];
  out << "]\n";
  if (!source.empty()) out << "source: " << YAML::Node(source) << "\n";
  std::ofstream f(path, std::ios::trunc);
  if (!f) throw std::runtime_error(path + ": cannot open for writing");
  f << out.str();
  if (!f.flush()) throw std::runtime_error(path + ": write failed");
}

void exportOpenCvCalibration(const CalibrationFile& file, const std::string& path) {
  const auto& c = file.calibration;
  auto intrinsics = [](const pipeline::PinholeModel& m) {
    return cv::Mat((cv::Mat_<double>(3, 3) << m.fx, 0, m.cx, 0, m.fy, m.cy, 0, 0, 1));
  };
  auto distortion = [](const pipeline::PinholeModel& m) {
    cv::Mat d(5, 1, CV_64F);
    for (int i = 0; i < 5; ++i) d.at<double>(i) = m.distortion[i];
    return d;
  };
  cv::Mat R(3, 3, CV_64F), t(3, 1, CV_64F);
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) R.at<double>(r, col) = c.R(r, col);
    t.at<double>(r) = c.t(r);
  }
  try {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    if (!fs.isOpened()) throw std::runtime_error(path + ": cannot open for writing");
    fs << "Kc" << intrinsics(c.camera) << "kc" << distortion(c.camera);
    fs << "Kp" << intrinsics(c.projector) << "kp" << distortion(c.projector);
    fs << "Rp" << R << "Tp" << t;
    if (file.errors)
      fs << "cam_error" << file.errors->camera_rms_px << "proj_error"
         << file.errors->projector_rms_px << "stereo_error" << file.errors->stereo_rms_px;
    fs << "frameWidth" << c.camera.width << "frameHeight" << c.camera.height;
    fs << "screenResX" << c.projector.width << "screenResY" << c.projector.height;
    fs.release();
  } catch (const cv::Exception& e) {
    throw std::runtime_error(path + ": cannot write OpenCV FileStorage: " + e.msg);
  }
}

}  // namespace sl::files
