// sl_calibrate: camera-projector calibration from board poses captured
// elsewhere (one folder of pattern images per pose), see README.md
// "Calibration".
//
//   sl_calibrate --poses DIR... --board COLSxROWS --square MM [options]
//   sl_calibrate --import-sl-sensor CAMERA.xml PROJECTOR.xml --out FILE.yaml
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>

#include "common/cli.h"
#include "common/frame_files.h"
#include "residual_plot.h"
#include "sl/files/calibration_io.h"
#include "sl/files/pattern_config.h"
#include "sl/pipeline/calibration.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/projector_response.h"

namespace {

namespace fs = std::filesystem;
namespace pl = sl::pipeline;

constexpr const char* kUsage =
    "usage: sl_calibrate --poses DIR... --board COLSxROWS --square MM [options]\n"
    "       sl_calibrate --import-sl-sensor CAMERA.xml PROJECTOR.xml --out FILE.yaml\n"
    "       sl_calibrate --projector-response RAMP_DIR [--levels L0,L1,...] --out FILE.yaml\n"
    "         (camera images of flat grey frames, e.g. from sl_patterns --ramp N, in natural\n"
    "         order; levels default k / (n - 1); writes the projector's response R(L))\n"
    "Each pose folder holds the camera images of one pattern sequence (png, bmp, tif, jpg,\n"
    "pgm), in projection order by the natural order of the numbers in their names (x_2\n"
    "before x_10; names that do not follow one numbering are refused), or as --list says.\n"
    "input:\n"
    "  --poses DIR...         pose folders, one pattern sequence of the board each\n"
    "  --pattern P            built-in 3+3_both (default) or a pattern file (YAML, see README)\n"
    "  --fringes N            periods of the built-in 3+3 pattern (default 16)\n"
    "  --projector WxH        projector resolution of the built-in pattern (default 1824x1140)\n"
    "  --bit-depth N          significant bits of 16-bit images (default 8 / 16 by type)\n"
    "  --list FILE            file names of one sequence, one per line in projection order,\n"
    "                         relative to each pose folder (frames a pattern file skips with\n"
    "                         skip_frames / frame_order -1 are listed too)\n"
    "  --exclude NAME         leave out the pose folder NAME (repeatable)\n"
    "  --secondary PRIMARY    calibrate a secondary camera against the projector of the\n"
    "                         calibration file PRIMARY (projector intrinsics fixed)\n"
    "  --import-sl-sensor CAMERA.xml PROJECTOR.xml  convert sl_sensor's calibration files\n"
    "  --projector-response RAMP_DIR  measure the projector's response from flat grey frames\n"
    "  --levels L0,L1,...     projector levels of the RAMP_DIR frames (default k / (n - 1))\n"
    "corners:\n"
    "  --board COLSxROWS      inner corners of the checkerboard (required)\n"
    "  --square MM            checkerboard square size (required)\n"
    "  --subpixel-radius PX   cornerSubPix half window (default 5)\n"
    "  --presmooth PX         Gaussian sigma before sub-pixel refinement (default 0)\n"
    "  --window-radius PX     local homography half window, camera px (default 15)\n"
    "  --min-valid N          minimum decoded pixels per window (default 100)\n"
    "  --min-modulation DN    decoder threshold on the 8-bit scale (default 8)\n"
    "  --keep-saturated       decode pixels with a saturated frame too (default: rejected)\n"
    "model:\n"
    "  --camera-fix-principal-point     camera cx, cy fixed at the image centre\n"
    "  --camera-fix-aspect-ratio        camera fx = fy\n"
    "  --camera-radial-terms N          camera radial distortion terms 0..3 (default 3)\n"
    "  --camera-no-tangential           camera tangential distortion fixed at 0\n"
    "  --projector-fix-principal-point  projector cx, cy fixed at the image centre\n"
    "  --projector-fix-aspect-ratio     projector fx = fy\n"
    "  --projector-radial-terms N       projector radial distortion terms 0..3 (default 3)\n"
    "  --projector-no-tangential        projector tangential distortion fixed at 0\n"
    "output:\n"
    "  --out FILE             calibration YAML (default calibration.yaml)\n"
    "  --export-opencv FILE   also write OpenCV FileStorage (.xml/.yaml/.json, SLStudio keys)\n"
    "  --report DIR           report.txt and residual plots (default: FILE without .yaml +\n"
    "                         _report)\n"
    "  --warn-px PX           per-corner residual warning threshold (default 1)\n"
    "  --max-focal-sigma PCT  warn when a focal length's 1-sigma exceeds PCT % (default 0.5)\n"
    "  --max-principal-sigma PX  warn when a principal point's 1-sigma exceeds PX (default 5)\n"
    "  --max-rms PX           stereo RMS reprojection error above which the result is refused\n"
    "                         (report written, calibration file not; default 2)\n"
    "  --accept               write the calibration even beyond --max-rms (exit 0)\n"
    "  -h, --help             this text\n"
    "exit codes: 0 ok, 1 error, 2 usage, 3 calibrated but stereo RMS beyond --max-rms\n";

[[noreturn]] void usageError(const std::string& message) {
  std::cerr << "sl_calibrate: " << message << "\n" << kUsage;
  std::exit(2);
}

double parseNumber(const std::string& option, const std::string& value) {
  if (const auto v = sl::tools::toNumber(value)) return *v;
  usageError(option + ": expected a number, got '" + value + "'");
}

int parseInt(const std::string& option, const std::string& value) {
  const double v = parseNumber(option, value);
  if (v != static_cast<int>(v)) usageError(option + ": expected an integer, got '" + value + "'");
  return static_cast<int>(v);
}

// "13x9" -> (13, 9).
std::pair<int, int> parseSize(const std::string& option, const std::string& value) {
  const auto x = value.find('x');
  if (x == std::string::npos) usageError(option + ": expected AxB, got '" + value + "'");
  return {parseInt(option, value.substr(0, x)), parseInt(option, value.substr(x + 1))};
}

struct Args {
  std::vector<std::string> poses;
  std::set<std::string> excluded;
  std::string pattern = "3+3_both";
  std::string list;
  int fringes = 16;
  int projector_width = 1824, projector_height = 1140;
  int bit_depth = 0;  // 0 = from the image type
  pl::Checkerboard board;
  pl::CornerDetectionOptions corners;
  pl::LocalHomographyOptions homography;
  float min_modulation = 8.0f;
  bool keep_saturated = false;
  double max_rms_px = 2.0;
  bool accept = false;
  pl::CalibrationOptions calibration;
  std::string secondary_of;
  std::string out = "calibration.yaml";
  std::string export_opencv;
  std::string report_dir;
  std::vector<std::string> import_sl_sensor;
  std::string response_dir;
  std::vector<double> levels;
};

Args parseArgs(int argc, char** argv) {
  Args a;
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty()) usageError("no arguments");
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& o = args[i];
    auto value = [&]() -> const std::string& {
      if (i + 1 >= args.size()) usageError(o + ": missing value");
      return args[++i];
    };
    auto device = [&](const std::string& prefix) -> pl::IntrinsicsOptions& {
      return prefix == "camera" ? a.calibration.camera : a.calibration.projector;
    };
    if (o == "--help" || o == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (o == "--poses") {
      while (i + 1 < args.size() && args[i + 1].rfind("--", 0) != 0) a.poses.push_back(args[++i]);
      if (a.poses.empty()) usageError("--poses: no folders given");
    } else if (o == "--projector-response") {
      a.response_dir = value();
    } else if (o == "--levels") {
      std::stringstream list(value());
      for (std::string item; std::getline(list, item, ',');) a.levels.push_back(parseNumber(o, item));
    } else if (o == "--import-sl-sensor") {
      a.import_sl_sensor = {value(), value()};
    } else if (o == "--list") {
      a.list = value();
    } else if (o == "--exclude") {
      a.excluded.insert(value());
    } else if (o == "--pattern") {
      a.pattern = value();
    } else if (o == "--fringes") {
      a.fringes = parseInt(o, value());
    } else if (o == "--projector") {
      std::tie(a.projector_width, a.projector_height) = parseSize(o, value());
    } else if (o == "--bit-depth") {
      a.bit_depth = parseInt(o, value());
    } else if (o == "--board") {
      std::tie(a.board.cols, a.board.rows) = parseSize(o, value());
    } else if (o == "--square") {
      a.board.square_mm = parseNumber(o, value());
    } else if (o == "--subpixel-radius") {
      a.corners.subpixel_radius_px = parseInt(o, value());
    } else if (o == "--presmooth") {
      a.corners.presmooth_sigma_px = parseNumber(o, value());
    } else if (o == "--window-radius") {
      a.homography.window_radius_px = parseInt(o, value());
    } else if (o == "--min-valid") {
      a.homography.min_valid_pixels = parseInt(o, value());
    } else if (o == "--min-modulation") {
      a.min_modulation = static_cast<float>(parseNumber(o, value()));
    } else if (o == "--keep-saturated") {
      a.keep_saturated = true;
    } else if (o == "--max-rms") {
      a.max_rms_px = parseNumber(o, value());
      if (!(a.max_rms_px > 0)) usageError("--max-rms must be > 0 (px)");
    } else if (o == "--accept") {
      a.accept = true;
    } else if (o == "--secondary") {
      a.secondary_of = value();
    } else if (o == "--out") {
      a.out = value();
    } else if (o == "--export-opencv") {
      a.export_opencv = value();
    } else if (o == "--report") {
      a.report_dir = value();
    } else if (o == "--max-focal-sigma") {
      a.calibration.max_focal_sigma_fraction = parseNumber(o, value()) / 100.0;
    } else if (o == "--max-principal-sigma") {
      a.calibration.max_principal_point_sigma_px = parseNumber(o, value());
    } else if (o == "--warn-px") {
      a.calibration.residual_warning_px = parseNumber(o, value());
    } else if (o.rfind("--camera-", 0) == 0 || o.rfind("--projector-", 0) == 0) {
      const std::string prefix = o.rfind("--camera-", 0) == 0 ? "camera" : "projector";
      const std::string flag = o.substr(prefix.size() + 3);
      if (flag == "fix-principal-point") {
        device(prefix).fix_principal_point = true;
      } else if (flag == "fix-aspect-ratio") {
        device(prefix).fix_aspect_ratio = true;
      } else if (flag == "no-tangential") {
        device(prefix).tangential = false;
      } else if (flag == "radial-terms") {
        const int n = parseInt(o, value());
        if (n < 0 || n > 3) usageError(o + ": must be 0..3");
        device(prefix).radial_terms = n;
      } else {
        usageError("unknown option " + o);
      }
    } else {
      usageError("unknown option " + o);
    }
  }
  if (!a.import_sl_sensor.empty() || !a.response_dir.empty()) return a;
  if (a.poses.empty()) usageError("--poses is required");
  if (a.board.cols <= 0 || a.board.rows <= 0) usageError("--board COLSxROWS is required");
  if (!(a.board.square_mm > 0)) usageError("--square MM is required (> 0)");
  if (a.report_dir.empty()) {
    fs::path p(a.out);
    a.report_dir = (p.parent_path() / (p.stem().string() + "_report")).string();
  }
  return a;
}

pl::PatternSpec patternSpec(const Args& a) {
  if (fs::exists(a.pattern)) return sl::files::loadPattern(a.pattern);
  if (a.pattern != "3+3_both")
    throw std::runtime_error("--pattern: '" + a.pattern +
                             "' is neither a pattern file nor the built-in 3+3_both");
  pl::PhaseShift33Pattern p;
  p.name = a.pattern;
  p.direction = pl::Direction::kBoth;
  p.fringes = a.fringes;
  p.projector_width = a.projector_width;
  p.projector_height = a.projector_height;
  return pl::toSpec(p);
}

std::string utcNow() {
  const std::time_t now = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return text;
}

void writeReport(std::ostream& out, const pl::CalibrationResult& r, const Args& a,
                 const std::vector<std::string>& skipped, bool primary_projector) {
  const auto& c = r.calibration;
  char line[256];
  out << "sl_calibrate report (" << utcNow() << ")\n";
  for (const std::string& s : skipped) out << "skipped: " << s << "\n";
  std::snprintf(line, sizeof line,
                "RMS reprojection error: camera %.3f px, projector %.3f px, stereo %.3f px\n",
                r.report.camera_rms_px, r.report.projector_rms_px, r.report.stereo_rms_px);
  out << line;
  for (const auto* m : {&c.camera, &c.projector}) {
    std::snprintf(line, sizeof line,
                  "%-9s %dx%d fx %.2f fy %.2f cx %.2f cy %.2f k [%.5f %.5f %.5f %.5f %.5f]\n",
                  m == &c.camera ? "camera" : "projector", m->width, m->height, m->fx, m->fy,
                  m->cx, m->cy, m->distortion[0], m->distortion[1], m->distortion[2],
                  m->distortion[3], m->distortion[4]);
    out << line;
  }
  const Eigen::Vector3d centre = -c.R.transpose() * c.t;
  std::snprintf(line, sizeof line,
                "projector pose X_p = R X_c + t: t [%.3f %.3f %.3f] mm, baseline %.3f mm, "
                "rotation %.3f deg\n",
                c.t.x(), c.t.y(), c.t.z(), centre.norm(),
                Eigen::AngleAxisd(c.R).angle() * 180.0 / std::numbers::pi);
  out << line;
  const auto& u = r.report.uncertainty;
  out << "1-sigma uncertainty (linearised least squares; assumes independent corner errors):\n";
  for (const auto* s : {&u.camera, &u.projector}) {
    if (s == &u.projector && primary_projector) {
      out << "  projector fixed (from the primary calibration)\n";
      continue;
    }
    const pl::PinholeModel& m = s == &u.camera ? c.camera : c.projector;
    std::snprintf(line, sizeof line,
                  "  %-9s fx %.2f (%.3f %%) fy %.2f (%.3f %%) cx %.2f cy %.2f px, "
                  "k [%.5f %.5f %.5f %.5f %.5f]\n",
                  s == &u.camera ? "camera" : "projector", s->fx, 100 * s->fx / m.fx, s->fy,
                  100 * s->fy / m.fy, s->cx, s->cy, s->distortion[0], s->distortion[1],
                  s->distortion[2], s->distortion[3], s->distortion[4]);
    out << line;
  }
  std::snprintf(line, sizeof line,
                "  pose      rotation [%.4f %.4f %.4f] deg, translation [%.3f %.3f %.3f] mm\n",
                u.rotation_deg.x(), u.rotation_deg.y(), u.rotation_deg.z(), u.translation_mm.x(),
                u.translation_mm.y(), u.translation_mm.z());
  out << line << "per pose (RMS px):\n";
  for (const auto& p : r.report.poses) {
    std::snprintf(line, sizeof line, "  %-12s %3d corners  camera %.3f  projector %.3f  stereo %.3f\n",
                  p.label.c_str(), p.corners, p.camera_rms_px, p.projector_rms_px,
                  p.stereo_rms_px);
    out << line;
  }
  out << "per-corner residuals (measured - reprojected, px) in residuals.csv; warnings above "
      << a.calibration.residual_warning_px << " px:\n";
  if (r.report.warnings.empty()) out << "  none\n";
  for (const std::string& w : r.report.warnings) out << "  warning: " << w << "\n";
  if (r.report.dominant_pose)
    out << "suggestion: re-run with --exclude " << *r.report.dominant_pose << "\n";
  for (const std::string& advice : r.report.advice) out << "suggestion: " << advice << "\n";
}

int run(const Args& a) {
  if (!a.response_dir.empty()) {
    const std::vector<std::string> files = a.list.empty()
                                               ? sl::tools::listFrameFiles(a.response_dir)
                                               : sl::tools::readFrameList(a.list, a.response_dir);
    std::vector<double> levels = a.levels;
    if (levels.empty())
      for (std::size_t k = 0; k < files.size(); ++k)
        levels.push_back(files.size() > 1 ? double(k) / double(files.size() - 1) : 0.0);
    if (levels.size() != files.size())
      throw std::runtime_error(a.response_dir + ": " + std::to_string(files.size()) +
                               " images but " + std::to_string(levels.size()) + " --levels");
    std::vector<cv::Mat> frames;
    for (const std::string& f : files) {
      cv::Mat image = cv::imread(f, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
      if (image.empty()) throw std::runtime_error(f + ": cannot read the image");
      frames.push_back(image);
    }
    const int bit_depth =
        a.bit_depth > 0 ? a.bit_depth : (frames.front().depth() == CV_8U ? 8 : 16);
    const std::vector<float> response =
        pl::estimateProjectorResponse(frames, levels, bit_depth);
    sl::files::saveProjectorResponse(
        response, "sl_calibrate --projector-response " + a.response_dir + " (" + utcNow() + ")",
        a.out);
    // The gamma a power law would have at mid grey, for the report.
    const double mid = response[response.size() / 2];
    std::cout << "projector response from " << files.size() << " levels: R(0.5) = " << mid
              << " (a gamma of " << std::log(std::max(mid, 1e-6)) / std::log(0.5) << ") -> "
              << a.out << "\n";
    return 0;
  }
  if (!a.import_sl_sensor.empty()) {
    auto file = sl::files::loadSlSensorCalibration(a.import_sl_sensor[0], a.import_sl_sensor[1]);
    sl::files::saveCalibration(file, a.out);
    if (!a.export_opencv.empty()) sl::files::exportOpenCvCalibration(file, a.export_opencv);
    std::cout << "imported " << file.source << " -> " << a.out << "\n";
    return 0;
  }
  const pl::PatternSpec spec = patternSpec(a);
  if (spec.direction != pl::Direction::kBoth)
    throw std::runtime_error("pattern '" + spec.name +
                             "' encodes one axis only: calibration needs both (direction both)");
  pl::DecoderOptions decoder_options;
  decoder_options.min_modulation = a.min_modulation;
  decoder_options.reject_saturated = !a.keep_saturated;
  const pl::Decoder decoder(spec, decoder_options);
  // Sinusoid-only sequences average to the offset A; others use the codec's A.
  const bool mean_shading = spec.family == pl::PatternFamily::kPhaseShift;

  std::optional<sl::files::CalibrationFile> primary;
  if (!a.secondary_of.empty()) {
    primary = sl::files::loadCalibration(a.secondary_of);
    const auto& projector = primary->calibration.projector;
    if (projector.width != spec.projector_width || projector.height != spec.projector_height)
      throw std::runtime_error("pattern '" + spec.name + "' is for a " +
                               std::to_string(spec.projector_width) + "x" +
                               std::to_string(spec.projector_height) + " projector, " +
                               a.secondary_of + "'s projector is " +
                               std::to_string(projector.width) + "x" +
                               std::to_string(projector.height));
  }

  std::vector<pl::BoardView> views;
  std::vector<std::string> skipped;
  cv::Size camera_size;
  for (const std::string& dir : a.poses) {
    const std::string label = fs::path(dir).filename().string().empty()
                                  ? fs::path(dir).parent_path().filename().string()
                                  : fs::path(dir).filename().string();
    if (a.excluded.count(label)) {
      skipped.push_back(label + " (excluded)");
      continue;
    }
    if (!fs::is_directory(dir)) throw std::runtime_error(dir + ": not a folder");
    const std::vector<std::string> files =
        a.list.empty() ? sl::tools::listFrameFiles(dir) : sl::tools::readFrameList(a.list, dir);
    if (static_cast<int>(files.size()) != decoder.codec().frameCount())
      throw std::runtime_error(dir + ": " + std::to_string(files.size()) + " images, pattern '" +
                               spec.name + "' has " +
                               std::to_string(decoder.codec().frameCount()) + " frames");
    std::vector<cv::Mat> frames;
    std::vector<cv::Mat> code_frames;  // without the frames the pattern skips
    for (std::size_t i = 0; i < files.size(); ++i) {
      cv::Mat image = cv::imread(files[i], cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
      if (image.empty()) throw std::runtime_error(files[i] + ": cannot read the image");
      frames.push_back(image);
      if (spec.frame_order.empty() || spec.frame_order[i] != pl::kSkippedFrame)
        code_frames.push_back(image);
    }
    if (camera_size.empty()) camera_size = frames.front().size();
    if (frames.front().size() != camera_size)
      throw std::runtime_error(dir + ": image size differs from the first pose's");
    const int bit_depth =
        a.bit_depth > 0 ? a.bit_depth : (frames.front().depth() == CV_8U ? 8 : 16);
    const pl::ProjectorMaps maps = decoder.decode(frames, bit_depth);
    const cv::Mat shading = mean_shading ? pl::meanImage(code_frames) : maps.offset;
    const pl::BoardViewResult result =
        pl::observeBoard(shading, maps, a.board, label, a.corners, a.homography);
    if (!result.view) {
      // Why, in numbers: how much of the image decoded, how much saturated.
      std::int64_t counts[5] = {0, 0, 0, 0, 0};
      for (int y = 0; y < maps.status.rows; ++y)
        for (int x = 0; x < maps.status.cols; ++x)
          ++counts[std::min<int>(maps.status.at<std::uint8_t>(y, x), 4)];
      const double total = static_cast<double>(maps.status.total());
      char numbers[320];
      std::snprintf(numbers, sizeof numbers,
                    "; corners found in the shading image: %d of %d; pixels: %.1f %% "
                    "decoded, %.1f %% saturated, %.1f %% low modulation, %.1f %% unwrap "
                    "inconsistent",
                    result.corners_found, a.board.cornerCount(),
                    100.0 * counts[0] / total, 100.0 * counts[2] / total,
                    100.0 * counts[1] / total, 100.0 * counts[3] / total);
      std::string reason = result.error + numbers;
      if (counts[2] > 0.05 * total)
        reason += a.keep_saturated
                      ? " (saturation: lower the exposure or the projector brightness)"
                      : " (saturation: lower the exposure or the projector brightness, or "
                        "decode saturated pixels with --keep-saturated)";
      std::cerr << "sl_calibrate: skipping " << reason << "\n";
      skipped.push_back(reason);
      continue;
    }
    std::cout << label << ": " << result.view->corner_ids.size() << " corners";
    if (result.view->corners_dropped > 0)
      std::cout << " (" << result.view->corners_dropped << " without a projector coordinate)";
    std::cout << "\n";
    views.push_back(*result.view);
  }
  if (views.size() < 3)
    throw std::runtime_error("only " + std::to_string(views.size()) +
                             " usable poses; calibration needs at least 3");

  const cv::Size projector_size(spec.projector_width, spec.projector_height);
  const pl::CalibrationResult result =
      primary ? pl::calibrateSecondaryCamera(views, a.board, camera_size,
                                             primary->calibration.projector, a.calibration)
              : pl::calibrateCameraProjector(views, a.board, camera_size, projector_size,
                                             a.calibration);

  fs::create_directories(a.report_dir);
  std::ostringstream report;
  writeReport(report, result, a, skipped, primary.has_value());
  std::cout << report.str();
  std::ofstream(fs::path(a.report_dir) / "report.txt") << report.str();
  {
    std::ofstream csv(fs::path(a.report_dir) / "residuals.csv");
    csv << "pose,corner,camera_dx_px,camera_dy_px,projector_dx_px,projector_dy_px\n";
    for (const auto& c : result.report.corners)
      csv << result.report.poses[c.pose].label << "," << c.corner_id << "," << c.camera_px.x
          << "," << c.camera_px.y << "," << c.projector_px.x << "," << c.projector_px.y << "\n";
  }
  const double warn = a.calibration.residual_warning_px;
  for (bool projector : {false, true}) {
    const std::string name = projector ? "residuals_projector.png" : "residuals_camera.png";
    const cv::Mat plot = sl::tools::plotResiduals(
        result.report, projector, warn,
        std::string(projector ? "projector" : "camera") + " residuals (px), RMS per pose");
    if (!cv::imwrite((fs::path(a.report_dir) / name).string(), plot))
      throw std::runtime_error((fs::path(a.report_dir) / name).string() + ": cannot write");
  }

  const bool beyond = result.report.stereo_rms_px > a.max_rms_px;
  if (beyond && !a.accept) {
    std::cerr << "sl_calibrate: stereo RMS reprojection error " << result.report.stereo_rms_px
              << " px is beyond --max-rms " << a.max_rms_px << " px: " << a.out
              << " not written (report in " << a.report_dir
              << "/; check the skipped poses and warnings above, or --accept)\n";
    return 3;
  }
  if (beyond)
    std::cerr << "sl_calibrate: stereo RMS " << result.report.stereo_rms_px
              << " px beyond --max-rms " << a.max_rms_px << " px, accepted (--accept)\n";
  sl::files::CalibrationFile file;
  file.calibration = result.calibration;
  file.errors = sl::files::CalibrationErrors{result.report.camera_rms_px,
                                              result.report.projector_rms_px,
                                              result.report.stereo_rms_px};
  file.board = sl::files::CalibrationBoard{a.board.cols, a.board.rows, a.board.square_mm};
  file.date = utcNow();
  std::string source = primary ? "sl_calibrate (secondary camera, projector of " +
                                     a.secondary_of + "): poses"
                               : "sl_calibrate: poses";
  for (const auto& v : views) source += " " + v.label;
  file.source = source;
  sl::files::saveCalibration(file, a.out);
  if (!a.export_opencv.empty()) sl::files::exportOpenCvCalibration(file, a.export_opencv);
  std::cout << "wrote " << a.out << " and " << a.report_dir << "/\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parseArgs(argc, argv);
  try {
    return run(args);
  } catch (const std::exception& e) {
    std::cerr << "sl_calibrate: " << e.what() << "\n";
    return 1;
  }
}
