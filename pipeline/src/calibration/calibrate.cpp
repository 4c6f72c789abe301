// Intrinsics of camera and projector, extrinsics with the intrinsics fixed,
// and the error report.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <sstream>
#include <tuple>

#include <Eigen/Dense>
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

std::string formatPx(double v) {
  std::ostringstream s;
  s.precision(3);
  s << std::fixed << v;
  return s.str();
}

// Intrinsics of one device from its views; rvecs/tvecs receive the board
// poses, sigma OpenCV's 1-sigma of the intrinsics. Returns OpenCV's RMS.
double calibrateIntrinsics(const std::vector<Points3>& board, const std::vector<Points2>& image,
                           cv::Size size, const IntrinsicsOptions& options, cv::Mat& K,
                           cv::Mat& distortion, std::vector<cv::Mat>& rvecs,
                           std::vector<cv::Mat>& tvecs, IntrinsicsSigma& sigma) {
  const int flags = calibrationFlags(options);
  // Initial guess from the board homographies (fx = fy), principal point at
  // the image centre (where it stays with fix_principal_point).
  K = cv::initCameraMatrix2D(board, image, size, 1.0);
  K.at<double>(0, 2) = (size.width - 1) * 0.5;
  K.at<double>(1, 2) = (size.height - 1) * 0.5;
  distortion = cv::Mat::zeros(5, 1, CV_64F);
  cv::Mat std_intrinsics, std_extrinsics, per_view;
  const double rms = cv::calibrateCamera(board, image, size, K, distortion, rvecs, tvecs,
                                         std_intrinsics, std_extrinsics, per_view, flags,
                                         kCriteria);
  // OpenCV before 4.7 divides the squared residuals of 2N coordinates by
  // N - p instead of 2N - p (opencv/opencv#19803, fixed by #22992): about
  // sqrt(2) too large. Undone here, so that the figures mean 1-sigma.
  double correction = 1.0;
#if CV_VERSION_MAJOR == 4 && CV_VERSION_MINOR < 7
  {
    double n = 0;
    for (const Points2& view : image) n += static_cast<double>(view.size());
    int free = (options.fix_aspect_ratio ? 1 : 2) + (options.fix_principal_point ? 0 : 2) +
               options.radial_terms + (options.tangential ? 2 : 0);
    const double p = free + 6.0 * static_cast<double>(image.size());
    if (n > p) correction = std::sqrt((n - p) / std::max(2 * n - p, 1.0));
  }
#endif
  // OpenCV's order: fx fy cx cy k1 k2 p1 p2 k3 ...
  auto at = [&](int i) {
    return i < static_cast<int>(std_intrinsics.total()) ? correction * std_intrinsics.at<double>(i)
                                                        : 0.0;
  };
  sigma.fx = at(0);
  sigma.fy = at(1);
  if (options.fix_aspect_ratio) {
    // fy follows fx: the same relative uncertainty.
    const double rel = std::max(sigma.fx / K.at<double>(0, 0), sigma.fy / K.at<double>(1, 1));
    sigma.fx = rel * K.at<double>(0, 0);
    sigma.fy = rel * K.at<double>(1, 1);
  }
  sigma.cx = at(2);
  sigma.cy = at(3);
  for (int i = 0; i < 5; ++i) sigma.distortion[i] = at(4 + i);
  return rms;
}

// Which intrinsics of one device are free, as columns of the joint problem:
// fx (and fy, or fx and fy together with a fixed aspect ratio), cx cy,
// the free distortion terms.
struct FreeIntrinsics {
  bool aspect_fixed = false;
  bool principal_point = true;
  std::array<bool, 5> distortion{};
  int count() const {
    int n = aspect_fixed ? 1 : 2;
    if (principal_point) n += 2;
    for (bool d : distortion) n += d;
    return n;
  }
};

FreeIntrinsics freeIntrinsics(const IntrinsicsOptions& o) {
  FreeIntrinsics f;
  f.aspect_fixed = o.fix_aspect_ratio;
  f.principal_point = !o.fix_principal_point;
  f.distortion = {o.radial_terms >= 1, o.radial_terms >= 2, o.tangential, o.tangential,
                  o.radial_terms >= 3};
  return f;
}

// Copies the intrinsic columns of a cv::projectPoints jacobian (2 rows per
// point; columns 6-7 focal, 8-9 principal point, 10-14 distortion) into the
// joint matrix at `col`.
void intrinsicColumns(const cv::Mat& jac, int point, const FreeIntrinsics& f, const cv::Mat& K,
                      double weight, Eigen::MatrixXd& J, int row, int col) {
  for (int k = 0; k < 2; ++k) {
    const double* jr = jac.ptr<double>(2 * point + k);
    int c = col;
    if (f.aspect_fixed) {
      J(row + k, c++) = weight * (jr[6] + jr[7] * K.at<double>(1, 1) / K.at<double>(0, 0));
    } else {
      J(row + k, c++) = weight * jr[6];
      J(row + k, c++) = weight * jr[7];
    }
    if (f.principal_point) {
      J(row + k, c++) = weight * jr[8];
      J(row + k, c++) = weight * jr[9];
    }
    for (int d = 0; d < 5; ++d)
      if (f.distortion[d]) J(row + k, c++) = weight * jr[10 + d];
  }
}

// 1-sigma of R (rotation vector, deg) and t (mm) from the joint linearised
// problem (CalibrationUncertainty).
void extrinsicUncertainty(const Correspondences& c, const cv::Mat& Kc, const cv::Mat& dc,
                          const std::vector<cv::Mat>& camera_rvecs,
                          const std::vector<cv::Mat>& camera_tvecs, const cv::Mat& Kp,
                          const cv::Mat& dp, const cv::Mat& R, const cv::Mat& T,
                          const FreeIntrinsics& camera_free,
                          const std::optional<FreeIntrinsics>& projector_free, double camera_rms,
                          double projector_rms, CalibrationUncertainty& out) {
  const int views = static_cast<int>(c.board.size());
  const int nc = camera_free.count(), np = projector_free ? projector_free->count() : 0;
  const int rt = nc + np;                 // R (3) and t (3) columns
  const int pose0 = rt + 6;               // then 6 per view
  const int params = pose0 + 6 * views;
  int rows = 0;
  for (const Points3& b : c.board) rows += 4 * static_cast<int>(b.size());
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(rows, params);
  // The projector's own calibration (its own board poses): np + 6 per view.
  Eigen::MatrixXd Jp = Eigen::MatrixXd::Zero(rows, np + 6 * views);
  // The RMS values are per point (2D): sqrt(2) times the per-coordinate sigma.
  const double wc = std::sqrt(2.0) / std::max(camera_rms, 1e-6),
               wp = std::sqrt(2.0) / std::max(projector_rms, 1e-6);
  cv::Mat rvec_rt;
  cv::Rodrigues(R, rvec_rt);
  int row = 0;
  for (int i = 0; i < views; ++i) {
    const int n = static_cast<int>(c.board[i].size());
    Points2 projected;
    cv::Mat jc, jp;
    cv::projectPoints(c.board[i], camera_rvecs[i], camera_tvecs[i], Kc, dc, projected, jc);
    cv::Mat rp, tp, dr3dr1, dr3dt1, dr3dr2, dr3dt2, dt3dr1, dt3dt1, dt3dr2, dt3dt2;
    cv::composeRT(camera_rvecs[i], camera_tvecs[i], rvec_rt, T, rp, tp, dr3dr1, dr3dt1, dr3dr2,
                  dr3dt2, dt3dr1, dt3dt1, dt3dr2, dt3dt2);
    cv::projectPoints(c.board[i], rp, tp, Kp, dp, projected, jp);
    // d(rp, tp) / d(camera pose, R t): 6 x 12.
    cv::Mat chain(6, 12, CV_64F, cv::Scalar(0));
    dr3dr1.copyTo(chain(cv::Rect(0, 0, 3, 3)));
    dr3dt1.copyTo(chain(cv::Rect(3, 0, 3, 3)));
    dr3dr2.copyTo(chain(cv::Rect(6, 0, 3, 3)));
    dr3dt2.copyTo(chain(cv::Rect(9, 0, 3, 3)));
    dt3dr1.copyTo(chain(cv::Rect(0, 3, 3, 3)));
    dt3dt1.copyTo(chain(cv::Rect(3, 3, 3, 3)));
    dt3dr2.copyTo(chain(cv::Rect(6, 3, 3, 3)));
    dt3dt2.copyTo(chain(cv::Rect(9, 3, 3, 3)));
    const cv::Mat jp_pose = jp(cv::Rect(0, 0, 6, jp.rows)) * chain;  // 2n x 12
    for (int j = 0; j < n; ++j) {
      for (int k = 0; k < 2; ++k) {
        const double* jr = jc.ptr<double>(2 * j + k);
        for (int q = 0; q < 6; ++q) J(row + k, pose0 + 6 * i + q) = wc * jr[q];
      }
      intrinsicColumns(jc, j, camera_free, Kc, wc, J, row, 0);
      row += 2;
      for (int k = 0; k < 2; ++k) {
        const double* jr = jp_pose.ptr<double>(2 * j + k);
        for (int q = 0; q < 6; ++q) J(row + k, pose0 + 6 * i + q) = wp * jr[q];
        for (int q = 0; q < 6; ++q) J(row + k, rt + q) = wp * jr[6 + q];
        const double* own = jp.ptr<double>(2 * j + k);
        for (int q = 0; q < 6; ++q) Jp(row + k, np + 6 * i + q) = wp * own[q];
      }
      if (projector_free) {
        intrinsicColumns(jp, j, *projector_free, Kp, wp, J, row, nc);
        Eigen::MatrixXd block = Eigen::MatrixXd::Zero(2, np);
        intrinsicColumns(jp, j, *projector_free, Kp, wp, block, 0, 0);
        Jp.block(row, 0, 2, np) = block;
      }
      row += 2;
    }
  }
  // Residual variances from the RMS (over m residuals): m / (m - p) for the
  // degrees of freedom the fit used.
  const double dof = static_cast<double>(rows) / std::max(rows - params, 1);
  auto inverse = [](const Eigen::MatrixXd& A) {
    return Eigen::MatrixXd(A.ldlt().solve(Eigen::MatrixXd::Identity(A.rows(), A.cols())));
  };
  // The estimator is two-step (each device's intrinsics on its own, then R,
  // t and the board poses with the intrinsics fixed), so its covariance is
  // the stereo step's own plus the intrinsics' errors carried through it:
  // C_e + S Sigma_i S^T with S = -(A^T A)^-1 A^T B.
  const Eigen::MatrixXd A = J.rightCols(params - rt);  // R, t, board poses
  const Eigen::MatrixXd B = J.leftCols(rt);            // intrinsics
  const Eigen::MatrixXd Ce = inverse(A.transpose() * A);
  const Eigen::MatrixXd S = -Ce * (A.transpose() * B);
  Eigen::MatrixXd Si = Eigen::MatrixXd::Zero(rt, rt);
  {
    // Camera alone: camera rows (projector rows of J zeroed), its
    // intrinsics and board poses.
    Eigen::MatrixXd Jc(rows, nc + 6 * views);
    Jc << J.leftCols(nc), J.rightCols(6 * views);
    for (int r = 2; r < rows; r += 4) Jc.middleRows(r, 2).setZero();
    Si.topLeftCorner(nc, nc) = inverse(Jc.transpose() * Jc).topLeftCorner(nc, nc);
    if (np > 0) Si.bottomRightCorner(np, np) = inverse(Jp.transpose() * Jp).topLeftCorner(np, np);
  }
  const Eigen::MatrixXd cov = (Ce + S * Si * S.transpose()) * dof;
  for (int q = 0; q < 3; ++q) {
    out.rotation_deg(q) = std::sqrt(std::max(cov(q, q), 0.0)) * 180.0 / CV_PI;
    out.translation_mm(q) = std::sqrt(std::max(cov(3 + q, 3 + q), 0.0));
  }
}

// Warnings on the uncertainties and advice on poses to add.
void adviseOnUncertainty(const Correspondences& c, const std::vector<cv::Mat>& camera_rvecs,
                         const std::vector<cv::Mat>& camera_tvecs, cv::Size camera_size,
                         cv::Size projector_size, const CameraProjectorCalibration& cal,
                         const CalibrationOptions& options, bool projector_estimated,
                         CalibrationReport& report) {
  const CalibrationUncertainty& u = report.uncertainty;
  bool focal = false, principal = false;
  auto check = [&](const char* device, const PinholeModel& m, const IntrinsicsSigma& s) {
    for (auto [name, f, sf] : {std::tuple{"fx", m.fx, s.fx}, std::tuple{"fy", m.fy, s.fy}}) {
      if (sf > options.max_focal_sigma_fraction * f) {
        focal = true;
        report.warnings.push_back(std::string(device) + " " + name + " uncertain: 1-sigma " +
                                  formatPx(sf) + " px = " + formatPx(100.0 * sf / f) +
                                  " % (threshold " +
                                  formatPx(100.0 * options.max_focal_sigma_fraction) + " %)");
      }
    }
    for (auto [name, sc] : {std::pair{"cx", s.cx}, std::pair{"cy", s.cy}}) {
      if (sc > options.max_principal_point_sigma_px) {
        principal = true;
        report.warnings.push_back(std::string(device) + " " + name + " uncertain: 1-sigma " +
                                  formatPx(sc) + " px (threshold " +
                                  formatPx(options.max_principal_point_sigma_px) + " px)");
      }
    }
  };
  check("camera", cal.camera, u.camera);
  if (projector_estimated) check("projector", cal.projector, u.projector);
  if (!focal && !principal) return;

  // Pose geometry: tilt of the board against the camera's axis, distance,
  // and which ninths of each image hold corners.
  double max_tilt = 0, near = 1e300, far = 0;
  for (std::size_t i = 0; i < camera_rvecs.size(); ++i) {
    cv::Mat Rb;
    cv::Rodrigues(camera_rvecs[i], Rb);
    const double nz = std::abs(Rb.at<double>(2, 2));  // board normal . optical axis
    max_tilt = std::max(max_tilt, std::acos(std::min(nz, 1.0)) * 180.0 / CV_PI);
    const double d = cv::norm(camera_tvecs[i]);
    near = std::min(near, d);
    far = std::max(far, d);
  }
  static const char* kCells[9] = {"top left",    "top",    "top right",
                                  "left",        "centre", "right",
                                  "bottom left", "bottom", "bottom right"};
  auto empty_cells = [&](const std::vector<Points2>& points, cv::Size size) {
    std::array<bool, 9> hit{};
    for (const Points2& view : points)
      for (const cv::Point2f& p : view) {
        const int cx = std::clamp(static_cast<int>(3 * p.x / size.width), 0, 2);
        const int cy = std::clamp(static_cast<int>(3 * p.y / size.height), 0, 2);
        hit[3 * cy + cx] = true;
      }
    std::string missing;
    for (int k = 0; k < 9; ++k)
      if (!hit[k]) missing += (missing.empty() ? "" : ", ") + std::string(kCells[k]);
    return missing;
  };
  const std::string camera_gaps = empty_cells(c.camera, camera_size);
  const std::string projector_gaps =
      projector_estimated ? empty_cells(c.projector, projector_size) : "";
  report.advice.push_back(std::to_string(c.board.size()) +
                          " poses; add more (10-20 is usual), each one different from the others");
  if (max_tilt < 30.0)
    report.advice.push_back("tilt the board more: the most tilted pose is " + formatPx(max_tilt) +
                            " deg from facing the camera; add poses tilted 30-45 deg to the left, "
                            "right, up and down (the focal length is fixed by the perspective of "
                            "tilted boards)");
  if (far < 1.2 * near)
    report.advice.push_back("vary the distance: the board is at " + formatPx(near) + " .. " +
                            formatPx(far) + " mm; add poses nearer and farther across the "
                            "working range");
  if (!camera_gaps.empty())
    report.advice.push_back("cover the camera's image: no corner in its " + camera_gaps);
  if (!projector_gaps.empty())
    report.advice.push_back("cover the projector's image: no corner in its " + projector_gaps +
                            " (the projector's principal point and distortion need corners "
                            "near its edges)");
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

// Everything after the intrinsics: per-corner residuals, R and t, per-pose
// and overall errors, warnings.
CalibrationResult finish(const std::vector<BoardView>& views, const Correspondences& c,
                         cv::Size camera_size, const cv::Mat& Kc, const cv::Mat& dc,
                         const std::vector<cv::Mat>& camera_rvecs,
                         const std::vector<cv::Mat>& camera_tvecs, cv::Size projector_size,
                         const cv::Mat& Kp, const cv::Mat& dp,
                         const std::vector<cv::Mat>& projector_rvecs,
                         const std::vector<cv::Mat>& projector_tvecs, double camera_rms,
                         double projector_rms, const IntrinsicsSigma& camera_sigma,
                         const std::optional<IntrinsicsSigma>& projector_sigma,
                         const CalibrationOptions& options) {
  CalibrationResult result;
  CalibrationReport& report = result.report;
  report.camera_rms_px = camera_rms;
  report.projector_rms_px = projector_rms;
  report.uncertainty.camera = camera_sigma;
  if (projector_sigma) report.uncertainty.projector = *projector_sigma;

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

  extrinsicUncertainty(c, Kc, dc, camera_rvecs, camera_tvecs, Kp, dp, R, T,
                       freeIntrinsics(options.camera),
                       projector_sigma ? std::optional(freeIntrinsics(options.projector))
                                       : std::nullopt,
                       camera_rms, projector_rms, report.uncertainty);
  adviseOnUncertainty(c, camera_rvecs, camera_tvecs, camera_size, projector_size,
                      result.calibration, options, projector_sigma.has_value(), report);

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
  IntrinsicsSigma camera_sigma, projector_sigma;
  const double camera_rms = calibrateIntrinsics(c.board, c.camera, camera_size, options.camera,
                                                Kc, dc, camera_rvecs, camera_tvecs, camera_sigma);
  const double projector_rms =
      calibrateIntrinsics(c.board, c.projector, projector_size, options.projector, Kp, dp,
                          projector_rvecs, projector_tvecs, projector_sigma);
  return finish(views, c, camera_size, Kc, dc, camera_rvecs, camera_tvecs, projector_size, Kp, dp,
                projector_rvecs, projector_tvecs, camera_rms, projector_rms, camera_sigma,
                projector_sigma, options);
}

CalibrationResult calibrateSecondaryCamera(const std::vector<BoardView>& views,
                                           const Checkerboard& board, cv::Size camera_size,
                                           const PinholeModel& projector,
                                           const CalibrationOptions& options) {
  const Correspondences c = gather(views, board);
  cv::Mat Kc, dc, Kp, dp;
  std::vector<cv::Mat> camera_rvecs, camera_tvecs;
  IntrinsicsSigma camera_sigma;
  const double camera_rms = calibrateIntrinsics(c.board, c.camera, camera_size, options.camera,
                                                Kc, dc, camera_rvecs, camera_tvecs, camera_sigma);
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
                projector_tvecs, camera_rms, projector_rms, camera_sigma, std::nullopt, options);
}

}  // namespace sl::pipeline
