// The sensor's static frames for /tf_static (docs/ros2.md "tf"): the config
// keys (dds.tf) and the transforms computed from them and the calibration.
// Pure: no DDS.
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "sl/daemon/config.h"
#include "sl/pipeline/camera_model.h"

namespace sl::files {
class YamlMap;
}  // namespace sl::files

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::YamlMap;

// Reads `dds.tf` (keys publish, parent_frame, base_frame, projector_frame,
// mount: {xyz: [m, m, m], rpy: [rad, rad, rad] | quaternion: [x, y, z, w]}).
// rpy as ROS has it: fixed axes, roll about x, then pitch about y, then yaw
// about z (q = Rz(yaw) Ry(pitch) Rx(roll)). Throws ConfigError naming the
// key: a quaternion whose norm is not 1 within 1e-3, both rpy and
// quaternion, a mount without parent_frame, bad frame names.
// mount: {hand_eye: FILE} instead takes the mount from an sl_handeye result
// (its mount: the first camera's optical frame in parent_frame); a relative
// FILE is relative to `base_dir` (the config file's folder).
void parseTfConfig(const YamlMap& m, TfConfig& tf, const std::filesystem::path& base_dir = {});

// One static transform: the pose of `child` in `parent`
// (p_parent = pose * p_child), translation in metres.
struct FrameTransform {
  std::string parent;
  std::string child;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
};

// The rotation taking a camera optical frame (x right, y down, z forward)
// into a REP 103 body frame (x forward, y left, z up) at the same origin.
Eigen::Matrix3d opticalToBody();

// The sensor's transforms: parent_frame -> base_frame (the mount; only with a
// parent_frame), base_frame -> each camera's optical frame (the first camera
// at base_frame's origin, rotated by opticalToBody(); the others placed by
// their calibrations against the common projector), and the first camera's
// optical frame -> projector_frame (X_p = R X_c + t inverted). `cameras`:
// camera id -> (its frame id, its calibration), the first camera's frame
// being `first_frame`. Throws ConfigError naming both keys when two frames share a name.
struct CameraFrame {
  std::string id;
  std::string frame_id;
  pipeline::CameraProjectorCalibration calibration;  // lengths in mm
};
std::vector<FrameTransform> sensorTransforms(const TfConfig& tf, const std::vector<CameraFrame>& cameras);

}  // namespace sl::daemon
