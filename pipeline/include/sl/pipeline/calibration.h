// Camera-projector calibration (paper section 3.4): checkerboard corners on
// the camera's shading image, projector coordinates of each corner from a
// local homography fitted to the decoded projector maps around it, then
// camera and projector intrinsics (the projector as an inverse camera, Brown
// model k1 k2 p1 p2 k3) and the camera-projector extrinsics with the
// intrinsics fixed. A secondary camera is calibrated against the projector
// with the projector intrinsics fixed to the primary pair's.
//
// Pure: no threads, no files. Units: board in mm, image points in px with
// the origin at the centre of the top-left pixel (the OpenCV and PinholeModel
// convention), projector points in projector px of the addressed resolution.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// A planar checkerboard. cols x rows counts inner corners (where four squares
// meet); the board frame has its origin at the first inner corner, x along a
// row of corners, y along a column, z = 0 on the board.
struct Checkerboard {
  int cols = 0;
  int rows = 0;
  double square_mm = 0;

  int cornerCount() const { return cols * rows; }
  // Corner `id` (row-major: id = row * cols + col) in the board frame, mm.
  cv::Point3f corner(int id) const;
  // Throws std::invalid_argument naming the bad field.
  void validate() const;
};

// How corners are found in the shading image.
struct CornerDetectionOptions {
  // Half size of cv::cornerSubPix's search window (camera px). It must stay
  // well inside one square: at most about a third of a square's image size.
  int subpixel_radius_px = 5;
  // Gaussian smoothing (sigma, camera px) of the shading image before the
  // sub-pixel refinement; 0 = none. Symmetric blur leaves the saddle point in
  // place but spreads a sharp edge's gradient over several pixels, which
  // removes most of cornerSubPix's pull towards pixel positions. Real lenses
  // blur enough already; the simulator (no optical blur) needs about 1 px.
  double presmooth_sigma_px = 0.0;
};

// The local homography of one corner (Moreno and Taubin): the decoded
// projector coordinates of the valid camera pixels within `window_radius_px`
// (square window) of the corner are fitted with a homography camera px ->
// projector px, robustly (least squares, then repeatedly without the pixels
// whose residual exceeds max(outlier_factor * median residual,
// min_outlier_px)), and the corner is mapped through it.
struct LocalHomographyOptions {
  int window_radius_px = 15;     // camera px
  int min_valid_pixels = 100;    // fewer valid pixels (or kept after trimming): corner dropped
  double outlier_factor = 3.0;   // times the median residual
  double min_outlier_px = 0.5;   // projector px: never trim residuals below this
  // Pixels whose modulation B is below this fraction of the window's 90th
  // percentile are left out (dark squares decode with more phase noise);
  // 0 = use every valid pixel. Needs ProjectorMaps::modulation.
  double min_relative_modulation = 0.5;
};

// Maps camera px -> projector px at `camera_px` by a local homography fitted
// to `maps.up` / `maps.vp` (both must be encoded, CV_32FC1, NaN = invalid).
// nullopt when too few valid pixels or inliers, or the fit is degenerate.
std::optional<cv::Point2f> projectorPointByLocalHomography(const ProjectorMaps& maps,
                                                           cv::Point2f camera_px,
                                                           const LocalHomographyOptions& options);

// Inner corners of `board` in `shading` (CV_8UC1, or CV_32FC1 / CV_16UC1,
// which are stretched to 8 bits), refined to sub-pixel precision, in board
// order (row-major), oriented so the first corner is the one nearer the image
// origin (a cols x rows board with both counts odd looks the same rotated by
// 180 degrees; this makes the choice deterministic). nullopt if the board is
// not found.
std::optional<std::vector<cv::Point2f>> detectCheckerboardCorners(
    const cv::Mat& shading, const Checkerboard& board, const CornerDetectionOptions& options);

// The mean of `frames` (CV_8UC1 or CV_16UC1, one size) as CV_32FC1 in
// camera DN: the shading image of a phase-shift sequence (every complete
// N-step set of a sinusoid averages to its offset A), with less noise than A
// of one set. Not for Gray codes (their frames do not average to a uniform
// level); use ProjectorMaps::offset there. Throws std::invalid_argument on an
// empty list or mismatched frames.
cv::Mat meanImage(const std::vector<cv::Mat>& frames);

// The correspondences of one board pose. Corners whose projector coordinate
// could not be found are left out (corner_ids says which remain).
struct BoardView {
  std::string label;
  std::vector<int> corner_ids;           // Checkerboard corner ids
  std::vector<cv::Point2f> camera_px;    // detected, sub-pixel
  std::vector<cv::Point2f> projector_px; // by local homography
  int corners_dropped = 0;               // detected corners without a projector point
};

// Detection + local homographies for one pose. nullopt with `error` set when
// the board is not found or fewer than half of its corners have a projector
// point.
struct BoardViewResult {
  std::optional<BoardView> view;
  std::string error;
  int corners_found = 0;           // in the shading image: 0, or every corner of the board
  int corners_with_projector = 0;  // of those, with a projector point
};
BoardViewResult observeBoard(const cv::Mat& shading, const ProjectorMaps& maps,
                             const Checkerboard& board, const std::string& label,
                             const CornerDetectionOptions& corner_options,
                             const LocalHomographyOptions& homography_options);

// Which intrinsics are estimated for one device.
struct IntrinsicsOptions {
  bool fix_principal_point = false;  // cx, cy stay at the image centre ((w-1)/2, (h-1)/2)
  bool fix_aspect_ratio = false;     // fx = fy
  int radial_terms = 3;              // 0..3: k1 (, k2 (, k3)) estimated, higher ones fixed at 0
  bool tangential = true;            // estimate p1, p2 (else fixed at 0)
};

struct CalibrationOptions {
  IntrinsicsOptions camera;
  IntrinsicsOptions projector;  // ignored by calibrateSecondaryCamera
  double residual_warning_px = 1.0;  // per-corner residuals above this are warned about
  // The worst pose "dominates" when its RMS exceeds this factor times the RMS
  // of all other poses together; the report then suggests dropping it.
  double dominant_pose_factor = 2.0;
  // Warnings on the estimated 1-sigma uncertainty (CalibrationUncertainty):
  // a focal length above this fraction of itself, a principal point
  // coordinate above this many px.
  double max_focal_sigma_fraction = 0.005;
  double max_principal_point_sigma_px = 5.0;
};

// 1-sigma standard deviations of one device's intrinsics (px; distortion
// unitless), 0 for parameters held fixed.
struct IntrinsicsSigma {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::array<double, 5> distortion{};  // k1 k2 p1 p2 k3
};

// Estimated 1-sigma uncertainty of a calibration from the linearised least
// squares problems at the solution: the intrinsics from each device's own
// cv::calibrateCamera (OpenCV's calibrateCameraExtended: residual variance
// times the diagonal of (J^T J)^-1; OpenCV < 4.7's factor sqrt(2) excess,
// opencv/opencv#19803, undone); R and t from the stereo step (R, t and the
// board poses with the intrinsics fixed; camera and projector residuals
// weighted by their own RMS) plus the intrinsics' covariance carried through
// it (C + S Sigma_int S^T, S the stereo solution's sensitivity to the
// intrinsics), as the two-step estimator has it. Assumes independent corner
// errors of equal variance per device: correlated or biased errors (blur, a
// wrong model) are not in it. test_calibration "[uncertainty]" compares it
// with the spread over noise seeds (within 0.8-1.35x).
struct CalibrationUncertainty {
  IntrinsicsSigma camera;
  IntrinsicsSigma projector;            // zeros for a secondary camera (projector fixed)
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();  // of R's rotation vector, per axis
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();
};

// One corner's reprojection residual, measured minus reprojected (px), for
// the camera and the projector each calibrated on its own (their board poses
// from their own calibrations).
struct CornerResidual {
  int pose = 0;  // index into CalibrationReport::poses
  int corner_id = 0;
  cv::Point2f camera_px;
  cv::Point2f projector_px;
};

struct PoseErrors {
  std::string label;
  int corners = 0;
  double camera_rms_px = 0;
  double projector_rms_px = 0;
  // Stereo step (board pose shared by camera and projector through R, t):
  // RMS over this pose's camera and projector points.
  double stereo_rms_px = 0;
};

struct CalibrationReport {
  double camera_rms_px = 0;     // over all corners of all poses
  // Secondary camera: the projector's RMS under its fixed intrinsics.
  double projector_rms_px = 0;
  double stereo_rms_px = 0;     // OpenCV's stereo RMS: over camera and projector points
  std::vector<PoseErrors> poses;
  std::vector<CornerResidual> corners;
  std::vector<std::string> warnings;  // corners above the threshold, a dominating pose,
                                      // parameters whose uncertainty passes its threshold
  std::optional<std::string> dominant_pose;  // label of a pose worth dropping, if any
  CalibrationUncertainty uncertainty;
  // Which poses to add when an uncertainty passes its threshold (tilt,
  // distance, coverage of the camera's and projector's images), one sentence
  // each; empty when nothing passes.
  std::vector<std::string> advice;
};

struct CalibrationResult {
  CameraProjectorCalibration calibration;
  CalibrationReport report;
};

// Primary pair: camera and projector intrinsics (each by cv::calibrateCamera
// with its IntrinsicsOptions), then R, t (X_p = R X_c + t, mm) by
// cv::stereoCalibrate with the intrinsics fixed. Needs >= 3 views with >= 6
// corners each; throws std::invalid_argument otherwise.
CalibrationResult calibrateCameraProjector(const std::vector<BoardView>& views,
                                           const Checkerboard& board, cv::Size camera_size,
                                           cv::Size projector_size,
                                           const CalibrationOptions& options);

// Step 4 of section 3.4: a secondary camera against the projector, whose
// intrinsics stay fixed to `projector` (from the primary pair). Returns the
// secondary camera's intrinsics and its X_p = R X_c + t.
CalibrationResult calibrateSecondaryCamera(const std::vector<BoardView>& views,
                                           const Checkerboard& board, cv::Size camera_size,
                                           const PinholeModel& projector,
                                           const CalibrationOptions& options);

}  // namespace sl::pipeline
