// sl_handeye: where the sensor sits on the robot (hand-eye calibration,
// pipeline/hand_eye.h; docs/metrology.md), from scans of a checkerboard at
// several robot poses.
//
//   sl_handeye --calibration C.yaml --robot-poses POSES.txt --board COLSxROWS --square MM
//              [--eye-to-hand] [--pattern P] [--fringes N] [--presmooth PX]
//              [--window-radius PX] [--out mount.yaml]
//
// POSES.txt: one scan per line, `FOLDER x y z qx qy qz qw`: the folder of that
// scan's frames (relative to the poses file) and the robot's flange pose in
// its base frame (base_from_gripper: translation in mm, unit quaternion x y z
// w as in geometry_msgs/Pose). '#' starts a comment.
#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "board_scans.h"
#include "sl/files/calibration_io.h"
#include "sl/pipeline/calibration.h"
#include "sl/pipeline/hand_eye.h"

namespace fs = std::filesystem;
namespace pl = sl::pipeline;

namespace {

constexpr const char* kHelp =
    "usage: sl_handeye --calibration FILE --robot-poses FILE --board COLSxROWS --square MM\n"
    "                  [options]\n"
    "Hand-eye calibration from board scans at several robot poses (docs/metrology.md).\n"
    "  --calibration FILE   camera-projector calibration of the sensor\n"
    "  --robot-poses FILE   one scan per line: FOLDER x y z qx qy qz qw (the scan's frames,\n"
    "                       relative to FILE; the flange pose base_from_gripper, mm and a unit\n"
    "                       quaternion); '#' starts a comment\n"
    "  --board COLSxROWS    inner corners of the board; --square MM its square size\n"
    "  --eye-to-hand        the sensor is fixed and the board on the flange (default: the\n"
    "                       sensor on the flange, the board fixed: eye-in-hand)\n"
    "  --pattern P          built-in 3+3_both (default) or a pattern file; both directions\n"
    "  --fringes N          periods of the built-in pattern (default 16)\n"
    "  --presmooth PX       Gaussian sigma before sub-pixel corner refinement (default 0)\n"
    "  --window-radius PX   local homography half window, camera px (default 15)\n"
    "  --out FILE           result YAML (default hand_eye.yaml)\n"
    "  -h, --help           this text\n"
    "exit codes: 0 ok, 1 error, 2 usage\n";

[[noreturn]] void usageError(const std::string& message) {
  std::cerr << "sl_handeye: " << message << "\n" << kHelp;
  std::exit(2);
}

struct RobotPose {
  std::string folder;
  Eigen::Isometry3d base_from_gripper = Eigen::Isometry3d::Identity();
};

std::vector<RobotPose> readRobotPoses(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::vector<RobotPose> poses;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (const auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    std::istringstream fields(line);
    RobotPose p;
    if (!(fields >> p.folder)) continue;  // blank
    double v[7];
    for (double& x : v)
      if (!(fields >> x) || !std::isfinite(x))
        throw std::runtime_error(path + ":" + std::to_string(number) +
                                 ": expected FOLDER x y z qx qy qz qw (7 numbers after the folder)");
    std::string extra;
    if (fields >> extra)
      throw std::runtime_error(path + ":" + std::to_string(number) + ": unexpected '" + extra +
                               "' after the quaternion");
    const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
    if (std::abs(q.norm() - 1) > 1e-3)
      throw std::runtime_error(path + ":" + std::to_string(number) + ": the quaternion's norm is " +
                               std::to_string(q.norm()) + ", not 1");
    p.base_from_gripper.linear() = q.normalized().toRotationMatrix();
    p.base_from_gripper.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
    p.folder = (fs::path(path).parent_path() / p.folder).string();
    poses.push_back(p);
  }
  if (poses.empty()) throw std::runtime_error(path + ": no robot pose");
  return poses;
}

void writePose(std::ostream& out, const char* name, const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  char text[256];
  std::snprintf(text, sizeof text,
                "%s:\n  translation_mm: [%.4f, %.4f, %.4f]\n  quaternion_xyzw: [%.9f, %.9f, "
                "%.9f, %.9f]\n",
                name, T.translation().x(), T.translation().y(), T.translation().z(), q.x(), q.y(),
                q.z(), q.w());
  out << text;
}

}  // namespace

int main(int argc, char** argv) {
  std::string calibration_path, poses_path, pattern = "3+3_both", out_path = "hand_eye.yaml";
  pl::Checkerboard board;
  bool eye_to_hand = false;
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
    } else if (o == "--robot-poses") {
      poses_path = value();
    } else if (o == "--eye-to-hand") {
      eye_to_hand = true;
    } else if (o == "--out") {
      out_path = value();
    } else {
      usageError("unknown option '" + o + "'");
    }
  }
  if (calibration_path.empty() || poses_path.empty())
    usageError("--calibration and --robot-poses are required");
  try {
    board.validate();
    const pl::CameraProjectorCalibration calibration =
        sl::files::loadCalibration(calibration_path).calibration;
    const pl::PatternSpec spec = sl::tools::boardScanPattern(
        pattern, fringes, calibration.projector.width, calibration.projector.height);
    std::vector<pl::HandEyeView> views;
    for (const RobotPose& pose : readRobotPoses(poses_path)) {
      const std::string label = fs::path(pose.folder).filename().string();
      const pl::BoardView seen = sl::tools::observeBoardScan(pose.folder, spec, board, scan, label);
      pl::HandEyeView v;
      v.label = label;
      v.base_from_gripper = pose.base_from_gripper;
      v.corner_ids = seen.corner_ids;
      v.points_mm = pl::triangulateBoardCorners(calibration, seen);
      views.push_back(std::move(v));
      std::cout << "sl_handeye: " << label << ": " << views.back().corner_ids.size()
                << " corners\n";
    }
    const pl::HandEyeResult r = pl::calibrateHandEye(
        views, board, eye_to_hand ? pl::HandEyeSetup::kEyeToHand : pl::HandEyeSetup::kEyeInHand);
    std::ostringstream yaml;
    yaml << "format: sl-sensor-hand-eye/1\n"
         << "setup: " << (eye_to_hand ? "eye-to-hand" : "eye-in-hand") << "\n"
         << "# mount: " << (eye_to_hand ? "base_from_camera" : "gripper_from_camera")
         << " (the camera's optical frame in the " << (eye_to_hand ? "robot base" : "flange")
         << " frame); target: " << (eye_to_hand ? "gripper_from_board" : "base_from_board")
         << "\n";
    writePose(yaml, "mount", r.mount);
    writePose(yaml, "target", r.target);
    char line[256];
    std::snprintf(line, sizeof line,
                  "sigma_rotation_deg: [%.5f, %.5f, %.5f]  # about the mount frame's axes\n"
                  "sigma_translation_mm: [%.4f, %.4f, %.4f]\nrms_mm: %.4f\n",
                  r.sigma_rotation_deg.x(), r.sigma_rotation_deg.y(), r.sigma_rotation_deg.z(),
                  r.sigma_translation_mm.x(), r.sigma_translation_mm.y(),
                  r.sigma_translation_mm.z(), r.rms_mm);
    yaml << line << "views:\n";
    for (std::size_t i = 0; i < views.size(); ++i) {
      std::snprintf(line, sizeof line, "  - {label: \"%s\", corners: %zu, rms_mm: %.4f}\n",
                    views[i].label.c_str(), views[i].corner_ids.size(), r.view_rms_mm[i]);
      yaml << line;
    }
    yaml << "advice:" << (r.advice.empty() ? " []\n" : "\n");
    for (const std::string& a : r.advice) yaml << "  - \"" << a << "\"\n";
    {
      const std::string temporary = out_path + ".part";
      std::ofstream out(temporary, std::ios::trunc);
      if (!(out << yaml.str()) || !out.flush())
        throw std::runtime_error(temporary + ": cannot write");
    }
    fs::rename(out_path + ".part", out_path);
    std::cout << yaml.str() << "sl_handeye: wrote " << out_path << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sl_handeye: " << e.what() << "\n";
    return 1;
  }
}
