// In-field verification of a camera-projector calibration from board scans,
// and an extrinsic-only correction of the projector's pose (docs/metrology.md).
//
// Verification, per board view, in millimetres: flatness (RMS and largest
// distance of the triangulated corners from their best plane), square size
// error (mean distance of neighbouring triangulated corners minus the
// nominal square), and camera-projector consistency: the board's pose from
// the camera alone (solvePnP on the camera corners) predicts where the
// projector should see each corner; the distance between the predicted and
// the decoded projector coordinate, taken to the board (projector px times
// depth / f_p), is what a moved projector changes first.
//
// Correction: R, t (X_p = R X_c + t) re-estimated with all intrinsics fixed,
// jointly with the board poses, from the camera and projector corners of a
// few views; 1-sigma from the linearised problem.
//
// Pure: no files, no threads (thread-safe).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "sl/pipeline/calibration.h"
#include "sl/pipeline/camera_model.h"

namespace sl::pipeline {

struct VerificationThresholds {
  double max_consistency_rms_mm = 0.1;  // camera-projector consistency, RMS over the corners
  double max_square_error_mm = 0.05;    // |mean square size - nominal|
  double max_flatness_rms_mm = 0.1;     // RMS distance from the corners' plane
};

struct ViewCheck {
  std::string label;
  int corners = 0;
  double flatness_rms_mm = 0, flatness_max_mm = 0;
  double square_mm = 0;         // mean triangulated neighbour distance
  double square_error_mm = 0;   // square_mm - nominal
  double consistency_rms_mm = 0, consistency_max_mm = 0;
  double consistency_rms_px = 0;  // the same in projector px
};

struct VerificationResult {
  std::vector<ViewCheck> views;
  // Over all views (corners pooled; square error: mean of the views').
  double flatness_rms_mm = 0, square_error_mm = 0, consistency_rms_mm = 0;
  bool pass = true;
  std::vector<std::string> failures;  // one sentence per threshold passed, with the numbers
};

// Throws std::invalid_argument on no view or a view with < 6 corners.
VerificationResult verifyCalibration(const CameraProjectorCalibration& calibration,
                                     const std::vector<BoardView>& views,
                                     const Checkerboard& board,
                                     const VerificationThresholds& thresholds = {});

struct ProjectorPoseCorrection {
  CameraProjectorCalibration calibration;  // intrinsics as given, R and t corrected
  Eigen::Vector3d sigma_rotation_deg = Eigen::Vector3d::Zero();   // about the projector's axes
  Eigen::Vector3d sigma_translation_mm = Eigen::Vector3d::Zero(); // of t
  double rotation_change_deg = 0;   // angle of R_new R_old^T
  double translation_change_mm = 0; // |t_new - t_old|
  double camera_rms_px = 0, projector_rms_px = 0;  // after the correction
};

// Needs >= 1 view with >= 6 corners (more views: smaller uncertainty).
ProjectorPoseCorrection correctProjectorPose(const CameraProjectorCalibration& calibration,
                                             const std::vector<BoardView>& views,
                                             const Checkerboard& board);

}  // namespace sl::pipeline
