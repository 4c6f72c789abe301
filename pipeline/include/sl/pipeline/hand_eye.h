// Hand-eye calibration: where the sensor sits on the robot, from scans of a
// checkerboard at several robot poses (docs/metrology.md).
//
// Eye-in-hand (sensor on the flange, board fixed in the cell): unknowns the
// mount X = gripper_from_camera and the board's pose Y = base_from_board.
// Eye-to-hand (sensor fixed, board on the flange): X = base_from_camera,
// Y = gripper_from_board. Both are solved as A_i X P_ik = Y B_k, with A_i the
// robot pose base_from_gripper (eye-in-hand) or its inverse (eye-to-hand),
// P_ik corner k of view i as the sensor measured it (triangulated, camera
// frame, mm) and B_k the corner on the board (board frame, mm): OpenCV's
// calibrateHandEye on the board poses fitted to each view's points gives the
// start, then a joint Levenberg-Marquardt refinement of X and Y over all 3D
// corner residuals.
//
// Pure: no files, no threads (thread-safe).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "sl/pipeline/calibration.h"
#include "sl/pipeline/camera_model.h"

namespace sl::pipeline {

// Corners of a board view triangulated with `calibration`: the camera ray of
// each corner cut with the plane of its projector column (or row, when the
// baseline is mostly vertical), both lenses' distortion applied. Camera frame,
// the calibration's unit (mm). Same order as view.corner_ids.
std::vector<Eigen::Vector3d> triangulateBoardCorners(const CameraProjectorCalibration& calibration,
                                                     const BoardView& view);

// The rigid pose camera_from_board that best maps the board's corners onto
// the measured points (Umeyama, no scale); *rms_mm: RMS 3D distance left.
Eigen::Isometry3d fitBoardPose(const Checkerboard& board, const std::vector<int>& corner_ids,
                               const std::vector<Eigen::Vector3d>& points, double* rms_mm = nullptr);

enum class HandEyeSetup { kEyeInHand, kEyeToHand };

struct HandEyeView {
  std::string label;
  Eigen::Isometry3d base_from_gripper = Eigen::Isometry3d::Identity();  // robot pose, mm
  std::vector<int> corner_ids;
  std::vector<Eigen::Vector3d> points_mm;  // measured corners, camera frame
};

struct HandEyeResult {
  // Eye-in-hand: gripper_from_camera; eye-to-hand: base_from_camera.
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  // Eye-in-hand: base_from_board; eye-to-hand: gripper_from_board.
  Eigen::Isometry3d target = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d initial_mount = Eigen::Isometry3d::Identity();  // calibrateHandEye (Tsai)
  // 1-sigma of the mount: rotation about the mount frame's own axes (deg) and
  // translation (mm, in the parent frame), the largest per parameter of the
  // linearised covariance with independent corner errors, the view-clustered
  // (sandwich) one and, from 4 views on, the leave-one-view-out jackknife's:
  // the last two also hold when a view's errors are correlated (robot pose
  // errors). Costs one refit per view.
  Eigen::Vector3d sigma_rotation_deg = Eigen::Vector3d::Zero();
  Eigen::Vector3d sigma_translation_mm = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();  // rad, mm
  double rms_mm = 0;                  // 3D corner residual over all views
  std::vector<double> view_rms_mm;    // per view (same order)
  std::vector<std::string> advice;    // which poses to add or check, one sentence each
};

struct HandEyeOptions {
  // A view whose RMS exceeds this factor times the median view's is named in
  // the advice (a robot pose that does not belong to its scan).
  double outlier_view_factor = 3.0;
  // Advice: rotation 1-sigma above this (deg) or translation above this (mm).
  double max_sigma_rotation_deg = 0.02;
  double max_sigma_translation_mm = 0.1;
};

// Needs >= 3 views with >= 4 corners each and rotations about at least two
// different axes; throws std::invalid_argument naming the view otherwise.
HandEyeResult calibrateHandEye(const std::vector<HandEyeView>& views, const Checkerboard& board,
                               HandEyeSetup setup, const HandEyeOptions& options = {});

}  // namespace sl::pipeline
