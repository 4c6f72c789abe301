// Intrinsics of camera and projector, extrinsics with the intrinsics fixed,
// and the error report.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "sl/pipeline/calibration.h"

namespace sl::pipeline {

namespace {

using Points2 = std::vector<cv::Point2f>;
using Points3 = std::vector<cv::Point3f>;

const cv::TermCriteria kCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, DBL_EPSILON);

// Correspondences in the layout OpenCV's calibration functions take.
struct Correspondences {
  std::vector<Points3> board;
  std::vector<Points2> camera;
  std::vector<Points2> projector;
};

Correspondences gather(const std::vector<BoardView>& views, const Checkerboard& board) {
  board.validate();
  if (views.size() < 3)
    throw std::invalid_argument("calibration needs at least 3 board poses, got " +
                                std::to_string(views.size()));
  Correspondences c;
  for (const BoardView& v : views) {
    if (v.corner_ids.size() != v.camera_px.size() || v.corner_ids.size() != v.projector_px.size())
      throw std::invalid_argument("board view '" + v.label + "': inconsistent corner lists");
    if (v.corner_ids.size() < 6)
      throw std::invalid_argument("board view '" + v.label + "': fewer than 6 corners");
    Points3 points;
    for (int id : v.corner_ids) {
      if (id < 0 || id >= board.cornerCount())
        throw std::invalid_argument("board view '" + v.label + "': corner id out of range");
      points.push_back(board.corner(id));
    }
    c.board.push_back(std::move(points));
    c.camera.push_back(v.camera_px);
    c.projector.push_back(v.projector_px);
  }
  return c;
}

int calibrationFlags(const IntrinsicsOptions& o) {
  if (o.radial_terms < 0 || o.radial_terms > 3)
    throw std::invalid_argument("radial_terms must be in 0..3");
  int flags = cv::CALIB_USE_INTRINSIC_GUESS;
  if (o.fix_principal_point) flags |= cv::CALIB_FIX_PRINCIPAL_POINT;
  if (o.fix_aspect_ratio) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  if (!o.tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  if (o.radial_terms < 1) flags |= cv::CALIB_FIX_K1;
  if (o.radial_terms < 2) flags |= cv::CALIB_FIX_K2;
  if (o.radial_terms < 3) flags |= cv::CALIB_FIX_K3;
  return flags;
}

// Intrinsics of one device from its views; rvecs/tvecs receive the board
// poses. Returns OpenCV's RMS.
double calibrateIntrinsics(const std::vector<Points3>& board, const std::vector<Points2>& image,
                           cv::Size size, const IntrinsicsOptions& options, cv::Mat& K,
                           cv::Mat& distortion, std::vector<cv::Mat>& rvecs,
                           std::vector<cv::Mat>& tvecs) {
  const int flags = calibrationFlags(options);
  // Initial guess from the board homographies (fx = fy), principal point at
  // the image centre (where it stays with fix_principal_point).
  K = cv::initCameraMatrix2D(board, image, size, 1.0);
  K.at<double>(0, 2) = (size.width - 1) * 0.5;
  K.at<double>(1, 2) = (size.height - 1) * 0.5;
  distortion = cv::Mat::zeros(5, 1, CV_64F);
  return cv::calibrateCamera(board, image, size, K, distortion, rvecs, tvecs, flags, kCriteria);
}

PinholeModel toPinhole(const cv::Mat& K, const cv::Mat& d, cv::Size size) {
  PinholeModel m;
  m.width = size.width;
  m.height = size.height;
  m.fx = K.at<double>(0, 0);
  m.fy = K.at<double>(1, 1);
  m.cx = K.at<double>(0, 2);
  m.cy = K.at<double>(1, 2);
  for (int i = 0; i < 5; ++i) m.distortion[i] = d.at<double>(i);
  return m;
}

void fromPinhole(const PinholeModel& m, cv::Mat& K, cv::Mat& d) {
  K = (cv::Mat_<double>(3, 3) << m.fx, 0, m.cx, 0, m.fy, m.cy, 0, 0, 1);
  d = cv::Mat(5, 1, CV_64F);
  for (int i = 0; i < 5; ++i) d.at<double>(i) = m.distortion[i];
}

// Measured minus reprojected, per corner.
Points2 residuals(const Points3& board, const Points2& measured, const cv::Mat& rvec,
                  const cv::Mat& tvec, const cv::Mat& K, const cv::Mat& d) {
  Points2 projected;
  cv::projectPoints(board, rvec, tvec, K, d, projected);
  Points2 r(measured.size());
  for (std::size_t i = 0; i < measured.size(); ++i) r[i] = measured[i] - projected[i];
  return r;
}

double sumSquares(const Points2& r) {
  double s = 0;
  for (const cv::Point2f& p : r) s += double(p.x) * p.x + double(p.y) * p.y;
  return s;
}

std::string formatPx(double v) {
  std::ostringstream s;
  s.precision(3);
  s << std::fixed << v;
  return s.str();
}

// Everything after the intrinsics: per-corner residuals, R and t, per-pose
// and overall errors, warnings.
CalibrationResult finish(const std::vector<BoardView>& views, const Correspondences& c,
                         cv::Size camera_size, const cv::Mat& Kc, const cv::Mat& dc,
                         const std::vector<cv::Mat>& camera_rvecs,
                         const std::vector<cv::Mat>& camera_tvecs, cv::Size projector_size,
                         const cv::Mat& Kp, const cv::Mat& dp,
                         const std::vector<cv::Mat>& projector_rvecs,
                         const std::vector<cv::Mat>& projector_tvecs, double camera_rms,
                         double projector_rms, const CalibrationOptions& options) {
  CalibrationResult result;
  CalibrationReport& report = result.report;
  report.camera_rms_px = camera_rms;
  report.projector_rms_px = projector_rms;

  cv::Mat Kc_fixed = Kc.clone(), dc_fixed = dc.clone(), Kp_fixed = Kp.clone(),
          dp_fixed = dp.clone();
  cv::Mat R, T, E, F, per_view;
  report.stereo_rms_px = cv::stereoCalibrate(c.board, c.camera, c.projector, Kc_fixed, dc_fixed,
                                             Kp_fixed, dp_fixed, camera_size, R, T, E, F,
                                             per_view, cv::CALIB_FIX_INTRINSIC, kCriteria);

  result.calibration.camera = toPinhole(Kc, dc, camera_size);
  result.calibration.projector = toPinhole(Kp, dp, projector_size);
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) result.calibration.R(r, col) = R.at<double>(r, col);
    result.calibration.t(r) = T.at<double>(r);
  }

  for (std::size_t i = 0; i < views.size(); ++i) {
    const Points2 rc =
        residuals(c.board[i], c.camera[i], camera_rvecs[i], camera_tvecs[i], Kc, dc);
    const Points2 rp =
        residuals(c.board[i], c.projector[i], projector_rvecs[i], projector_tvecs[i], Kp, dp);
    const int n = static_cast<int>(rc.size());
    PoseErrors pose;
    pose.label = views[i].label;
    pose.corners = n;
    pose.camera_rms_px = std::sqrt(sumSquares(rc) / n);
    pose.projector_rms_px = std::sqrt(sumSquares(rp) / n);
    const double e_camera = per_view.at<double>(int(i), 0);
    const double e_projector = per_view.at<double>(int(i), 1);
    pose.stereo_rms_px = std::sqrt(0.5 * (e_camera * e_camera + e_projector * e_projector));
    report.poses.push_back(pose);
    for (int k = 0; k < n; ++k) {
      report.corners.push_back({static_cast<int>(i), views[i].corner_ids[k], rc[k], rp[k]});
      const double ec = std::hypot(rc[k].x, rc[k].y), ep = std::hypot(rp[k].x, rp[k].y);
      const double worst = std::max(ec, ep);
      if (worst > options.residual_warning_px)
        report.warnings.push_back("pose " + views[i].label + " corner " +
                                  std::to_string(views[i].corner_ids[k]) +
                                  ": residual camera " + formatPx(ec) + " px, projector " +
                                  formatPx(ep) + " px (above " +
                                  formatPx(options.residual_warning_px) + " px)");
    }
  }

  // Does the worst pose dominate? Compare its stereo RMS with the RMS of
  // all other poses together.
  if (views.size() >= 4) {
    const auto worst = std::max_element(
        report.poses.begin(), report.poses.end(),
        [](const PoseErrors& a, const PoseErrors& b) { return a.stereo_rms_px < b.stereo_rms_px; });
    double others_sum = 0;
    int others_n = 0;
    for (const PoseErrors& p : report.poses) {
      if (&p == &*worst) continue;
      others_sum += p.stereo_rms_px * p.stereo_rms_px * p.corners;
      others_n += p.corners;
    }
    const double others_rms = std::sqrt(others_sum / std::max(others_n, 1));
    if (worst->stereo_rms_px > options.dominant_pose_factor * others_rms) {
      report.dominant_pose = worst->label;
      report.warnings.push_back("pose " + worst->label + " dominates the error (stereo RMS " +
                                formatPx(worst->stereo_rms_px) + " px, the other poses " +
                                formatPx(others_rms) + " px): consider excluding it");
    }
  }
  return result;
}

}  // namespace

CalibrationResult calibrateCameraProjector(const std::vector<BoardView>& views,
                                           const Checkerboard& board, cv::Size camera_size,
                                           cv::Size projector_size,
                                           const CalibrationOptions& options) {
  const Correspondences c = gather(views, board);
  cv::Mat Kc, dc, Kp, dp;
  std::vector<cv::Mat> camera_rvecs, camera_tvecs, projector_rvecs, projector_tvecs;
  const double camera_rms = calibrateIntrinsics(c.board, c.camera, camera_size, options.camera,
                                                Kc, dc, camera_rvecs, camera_tvecs);
  const double projector_rms =
      calibrateIntrinsics(c.board, c.projector, projector_size, options.projector, Kp, dp,
                          projector_rvecs, projector_tvecs);
  return finish(views, c, camera_size, Kc, dc, camera_rvecs, camera_tvecs, projector_size, Kp, dp,
                projector_rvecs, projector_tvecs, camera_rms, projector_rms, options);
}

CalibrationResult calibrateSecondaryCamera(const std::vector<BoardView>& views,
                                           const Checkerboard& board, cv::Size camera_size,
                                           const PinholeModel& projector,
                                           const CalibrationOptions& options) {
  const Correspondences c = gather(views, board);
  cv::Mat Kc, dc, Kp, dp;
  std::vector<cv::Mat> camera_rvecs, camera_tvecs;
  const double camera_rms = calibrateIntrinsics(c.board, c.camera, camera_size, options.camera,
                                                Kc, dc, camera_rvecs, camera_tvecs);
  // The projector's board poses under its fixed intrinsics, for the report.
  fromPinhole(projector, Kp, dp);
  std::vector<cv::Mat> projector_rvecs(views.size()), projector_tvecs(views.size());
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    cv::solvePnP(c.board[i], c.projector[i], Kp, dp, projector_rvecs[i], projector_tvecs[i]);
    cv::solvePnPRefineLM(c.board[i], c.projector[i], Kp, dp, projector_rvecs[i],
                         projector_tvecs[i]);
    sum += sumSquares(residuals(c.board[i], c.projector[i], projector_rvecs[i],
                                projector_tvecs[i], Kp, dp));
    n += static_cast<int>(c.projector[i].size());
  }
  const double projector_rms = std::sqrt(sum / n);
  return finish(views, c, camera_size, Kc, dc, camera_rvecs, camera_tvecs,
                cv::Size(projector.width, projector.height), Kp, dp, projector_rvecs,
                projector_tvecs, camera_rms, projector_rms, options);
}

}  // namespace sl::pipeline
