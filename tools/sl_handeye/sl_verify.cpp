// sl_verify: does a camera-projector calibration still hold? Scans of a board
// in view -> flatness, square size error and camera-projector consistency in
// mm against pass / fail thresholds (pipeline/calibration_check.h), and on
// request a new calibration with the projector's pose re-estimated
// (docs/metrology.md).
//
//   sl_verify --calibration C.yaml --board COLSxROWS --square MM --scans DIR...
//             [--correct NEW.yaml] [thresholds] [--pattern P] [--fringes N]
//             [--presmooth PX] [--window-radius PX]
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "board_scans.h"
#include "sl/files/calibration_io.h"
#include "sl/pipeline/calibration_check.h"

namespace fs = std::filesystem;
namespace pl = sl::pipeline;

namespace {

constexpr int kExitFailed = 4;

constexpr const char* kHelp =
    "usage: sl_verify --calibration FILE --board COLSxROWS --square MM --scans DIR... [options]\n"
    "Checks a calibration on scans of a board (docs/metrology.md).\n"
    "  --calibration FILE       the camera-projector calibration to check\n"
    "  --scans DIR...           one folder of frames per board view (1-5 views, tilted)\n"
    "  --board COLSxROWS        inner corners; --square MM square size\n"
    "  --max-consistency MM     camera-projector consistency RMS threshold (default 0.1)\n"
    "  --max-square-error MM    |square size error| threshold (default 0.05)\n"
    "  --max-flatness MM        board flatness RMS threshold (default 0.1)\n"
    "  --correct NEW.yaml       also re-estimate the projector's pose (intrinsics kept) and\n"
    "                           write the corrected calibration to NEW.yaml (a new file: never\n"
    "                           the checked one, never an existing file)\n"
    "  --pattern P              built-in 3+3_both (default) or a pattern file; both directions\n"
    "  --fringes N              periods of the built-in pattern (default 16)\n"
    "  --presmooth PX           Gaussian sigma before sub-pixel corner refinement (default 0)\n"
    "  --window-radius PX       local homography half window, camera px (default 15)\n"
    "  -h, --help               this text\n"
    "exit codes: 0 the calibration holds, 1 error, 2 usage, 4 it does not hold (with\n"
    "--correct: the check of the calibration given, before the correction)\n";

[[noreturn]] void usageError(const std::string& message) {
  std::cerr << "sl_verify: " << message << "\n" << kHelp;
  std::exit(2);
}

double number(const std::string& option, const std::string& value) {
  try {
    return sl::tools::optionNumber(option, value);
  } catch (const std::invalid_argument& e) {
    usageError(e.what());
  }
}

void print(const char* title, const pl::VerificationResult& r) {
  std::printf("%s\n", title);
  for (const pl::ViewCheck& v : r.views)
    std::printf("  %s: %d corners, flatness %.3f mm RMS (max %.3f), square %.4f mm (%+.4f), "
                "consistency %.3f mm RMS (max %.3f; %.3f projector px)\n",
                v.label.c_str(), v.corners, v.flatness_rms_mm, v.flatness_max_mm, v.square_mm,
                v.square_error_mm, v.consistency_rms_mm, v.consistency_max_mm,
                v.consistency_rms_px);
  std::printf("  all views: flatness %.3f mm RMS, square error %+.4f mm, consistency %.3f mm RMS "
              "-> %s\n",
              r.flatness_rms_mm, r.square_error_mm, r.consistency_rms_mm,
              r.pass ? "PASS" : "FAIL");
  for (const std::string& f : r.failures) std::printf("  %s\n", f.c_str());
}

std::string utcNow() {
  const std::time_t now = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return text;
}

}  // namespace

int main(int argc, char** argv) {
  std::string calibration_path, pattern = "3+3_both", correct_path;
  std::vector<std::string> scans;
  pl::Checkerboard board;
  pl::VerificationThresholds thresholds;
  int fringes = 16;
  sl::tools::BoardScanOptions scan;
  // The board-scan options both metrology tools share (board_scans.h).
  const auto takeShared = [&](const std::string& o, const std::function<std::string()>& value) {
    try {
      return sl::tools::takeBoardScanOption(o, value, board, pattern, fringes, scan);
    } catch (const std::invalid_argument& e) {
      usageError(e.what());
    }
  };
  for (int i = 1; i < argc; ++i) {
    const std::string o = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usageError(o + ": missing value");
      return argv[++i];
    };
    if (o == "-h" || o == "--help") {
      std::cout << kHelp;
      return 0;
    } else if (o == "--calibration") {
      calibration_path = value();
    } else if (takeShared(o, value)) {
    } else if (o == "--scans") {
      while (i + 1 < argc && std::string(argv[i + 1]).rfind("--", 0) != 0) scans.push_back(argv[++i]);
      if (scans.empty()) usageError("--scans: no folders given");
    } else if (o == "--max-consistency") {
      thresholds.max_consistency_rms_mm = number(o, value());
    } else if (o == "--max-square-error") {
      thresholds.max_square_error_mm = number(o, value());
    } else if (o == "--max-flatness") {
      thresholds.max_flatness_rms_mm = number(o, value());
    } else if (o == "--correct") {
      correct_path = value();
    } else {
      usageError("unknown option '" + o + "'");
    }
  }
  if (calibration_path.empty() || scans.empty())
    usageError("--calibration and --scans are required");
  try {
    board.validate();
    if (!correct_path.empty()) {
      // Never replace a calibration: not the checked one, not any other.
      if (fs::exists(correct_path))
        throw std::runtime_error("--correct " + correct_path +
                                 ": the file exists; give a new name (the old calibration is "
                                 "kept as it is)");
    }
    const sl::files::CalibrationFile file = sl::files::loadCalibration(calibration_path);
    const pl::CameraProjectorCalibration& calibration = file.calibration;
    const pl::PatternSpec spec = sl::tools::boardScanPattern(
        pattern, fringes, calibration.projector.width, calibration.projector.height);
    std::vector<pl::BoardView> views;
    for (const std::string& folder : scans)
      views.push_back(sl::tools::observeBoardScan(folder, spec, board, scan,
                                                  fs::path(folder).filename().string()));
    const pl::VerificationResult check = pl::verifyCalibration(calibration, views, board, thresholds);
    print(("sl_verify: " + calibration_path).c_str(), check);
    if (!correct_path.empty()) {
      const pl::ProjectorPoseCorrection fix = pl::correctProjectorPose(calibration, views, board);
      char text[512];
      std::snprintf(text, sizeof text,
                    "projector pose corrected: rotation changed by %.4f deg (1-sigma %.4f %.4f "
                    "%.4f about the projector's axes), translation by %.4f mm (1-sigma %.4f %.4f "
                    "%.4f); residuals camera %.3f px, projector %.3f px RMS",
                    fix.rotation_change_deg, fix.sigma_rotation_deg.x(), fix.sigma_rotation_deg.y(),
                    fix.sigma_rotation_deg.z(), fix.translation_change_mm,
                    fix.sigma_translation_mm.x(), fix.sigma_translation_mm.y(),
                    fix.sigma_translation_mm.z(), fix.camera_rms_px, fix.projector_rms_px);
      std::printf("sl_verify: %s\n", text);
      const pl::VerificationResult recheck =
          pl::verifyCalibration(fix.calibration, views, board, thresholds);
      print("sl_verify: the corrected calibration on the same scans", recheck);
      sl::files::CalibrationFile corrected = file;
      corrected.calibration = fix.calibration;
      corrected.errors.reset();
      corrected.date = utcNow();
      corrected.source = "sl_verify --correct of " + calibration_path + " on " +
                         std::to_string(views.size()) + " board views: " + text;
      sl::files::saveCalibration(corrected, correct_path);
      std::printf("sl_verify: wrote %s (%s left as it was)\n", correct_path.c_str(),
                  calibration_path.c_str());
    }
    return check.pass ? 0 : kExitFailed;
  } catch (const std::exception& e) {
    std::cerr << "sl_verify: " << e.what() << "\n";
    return 1;
  }
}
