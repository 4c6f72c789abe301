#include "sl/pipeline/calibration_check.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

#include "least_squares.h"
#include "sl/pipeline/hand_eye.h"

namespace sl::pipeline {

namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

std::string format(const char* f, double a, double b = 0, double c = 0) {
  char text[256];
  std::snprintf(text, sizeof text, f, a, b, c);
  return text;
}

void checkView(const BoardView& v, const Checkerboard& board) {
  if (v.corner_ids.size() < 6 || v.camera_px.size() != v.corner_ids.size() ||
      v.projector_px.size() != v.corner_ids.size())
    throw std::invalid_argument("board view '" + v.label +
                                "': needs >= 6 corners with camera and projector points");
  for (int id : v.corner_ids)
    if (id < 0 || id >= board.cornerCount())
      throw std::invalid_argument("board view '" + v.label + "': corner id out of range");
}

cv::Mat cameraMatrix(const PinholeModel& m) {
  return (cv::Mat_<double>(3, 3) << m.fx, 0, m.cx, 0, m.fy, m.cy, 0, 0, 1);
}

cv::Mat distortion(const PinholeModel& m) {
  return (cv::Mat_<double>(1, 5) << m.distortion[0], m.distortion[1], m.distortion[2],
          m.distortion[3], m.distortion[4]);
}

// camera_from_board from the camera corners alone.
Eigen::Isometry3d cameraPose(const PinholeModel& camera, const BoardView& v,
                             const Checkerboard& board) {
  std::vector<cv::Point3f> object;
  for (int id : v.corner_ids) object.push_back(board.corner(id));
  cv::Mat rvec, tvec;
  const cv::Mat K = cameraMatrix(camera), d = distortion(camera);
  cv::solvePnP(object, v.camera_px, K, d, rvec, tvec);
  cv::solvePnPRefineLM(object, v.camera_px, K, d, rvec, tvec);
  cv::Mat R;
  cv::Rodrigues(rvec, R);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) pose.linear()(r, c) = R.at<double>(r, c);
    pose.translation()(r) = tvec.at<double>(r);
  }
  return pose;
}

Eigen::Vector3d cornerOf(const Checkerboard& board, int id) {
  const cv::Point3f b = board.corner(id);
  return {b.x, b.y, b.z};
}

}  // namespace

VerificationResult verifyCalibration(const CameraProjectorCalibration& c,
                                     const std::vector<BoardView>& views,
                                     const Checkerboard& board,
                                     const VerificationThresholds& thresholds) {
  board.validate();
  if (views.empty()) throw std::invalid_argument("verification needs at least one board view");
  VerificationResult result;
  double flat_sum = 0, consistency_sum = 0, square_sum = 0;
  long long n_total = 0;
  for (const BoardView& v : views) {
    checkView(v, board);
    ViewCheck check;
    check.label = v.label;
    const int n = static_cast<int>(v.corner_ids.size());
    check.corners = n;
    const std::vector<Eigen::Vector3d> X = triangulateBoardCorners(c, v);
    // Flatness: distances from the least-squares plane.
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& p : X) centroid += p;
    centroid /= n;
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    for (const auto& p : X) scatter += (p - centroid) * (p - centroid).transpose();
    const Eigen::Vector3d normal =
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvectors().col(0);
    double flat_sq = 0;
    for (const auto& p : X) {
      const double d = (p - centroid).dot(normal);
      flat_sq += d * d;
      check.flatness_max_mm = std::max(check.flatness_max_mm, std::abs(d));
    }
    check.flatness_rms_mm = std::sqrt(flat_sq / n);
    // Square size: neighbours along rows and columns of the board.
    std::vector<int> index(board.cornerCount(), -1);
    for (int k = 0; k < n; ++k) index[v.corner_ids[k]] = k;
    double spacing = 0;
    int pairs = 0;
    for (int k = 0; k < n; ++k) {
      const int id = v.corner_ids[k];
      for (int next : {id % board.cols + 1 < board.cols ? id + 1 : -1,
                       id + board.cols < board.cornerCount() ? id + board.cols : -1})
        if (next >= 0 && index[next] >= 0) {
          spacing += (X[index[next]] - X[k]).norm();
          ++pairs;
        }
    }
    check.square_mm = pairs > 0 ? spacing / pairs : std::nan("");
    check.square_error_mm = check.square_mm - board.square_mm;
    // Consistency: projector corners predicted from the camera's board pose.
    const Eigen::Isometry3d pose = cameraPose(c.camera, v, board);
    double px_sq = 0, mm_sq = 0;
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector3d Xp = c.R * (pose * cornerOf(board, v.corner_ids[k])) + c.t;
      const Eigen::Vector2d predicted = c.projector.project(Xp);
      const double px = (predicted - Eigen::Vector2d(v.projector_px[k].x, v.projector_px[k].y)).norm();
      const double mm = px * Xp.z() / (0.5 * (c.projector.fx + c.projector.fy));
      px_sq += px * px;
      mm_sq += mm * mm;
      check.consistency_max_mm = std::max(check.consistency_max_mm, mm);
    }
    check.consistency_rms_px = std::sqrt(px_sq / n);
    check.consistency_rms_mm = std::sqrt(mm_sq / n);
    flat_sum += flat_sq;
    consistency_sum += mm_sq;
    square_sum += check.square_error_mm;
    n_total += n;
    result.views.push_back(check);
  }
  result.flatness_rms_mm = std::sqrt(flat_sum / double(n_total));
  result.consistency_rms_mm = std::sqrt(consistency_sum / double(n_total));
  result.square_error_mm = square_sum / double(views.size());
  if (result.consistency_rms_mm > thresholds.max_consistency_rms_mm)
    result.failures.push_back(format(
        "camera-projector consistency %.3f mm RMS exceeds %.3f mm: the projector has moved "
        "against the camera (sl_verify --correct re-estimates its pose) or the intrinsics no "
        "longer hold",
        result.consistency_rms_mm, thresholds.max_consistency_rms_mm));
  if (std::abs(result.square_error_mm) > thresholds.max_square_error_mm)
    result.failures.push_back(format(
        "square size off by %+.3f mm (beyond %.3f mm): the measured scale is wrong (a moved "
        "projector, or a wrong --square)",
        result.square_error_mm, thresholds.max_square_error_mm));
  if (result.flatness_rms_mm > thresholds.max_flatness_rms_mm)
    result.failures.push_back(format(
        "board flatness %.3f mm RMS exceeds %.3f mm: the calibration bends the board (or the "
        "board is not flat)",
        result.flatness_rms_mm, thresholds.max_flatness_rms_mm));
  result.pass = result.failures.empty();
  return result;
}

ProjectorPoseCorrection correctProjectorPose(const CameraProjectorCalibration& c,
                                             const std::vector<BoardView>& views,
                                             const Checkerboard& board) {
  board.validate();
  if (views.empty()) throw std::invalid_argument("the correction needs at least one board view");
  std::vector<Eigen::Isometry3d> poses;
  int corners = 0;
  for (const BoardView& v : views) {
    checkView(v, board);
    poses.push_back(cameraPose(c.camera, v, board));
    corners += static_cast<int>(v.corner_ids.size());
  }
  const int values = 4 * corners;
  const int params = 6 + 6 * static_cast<int>(views.size());
  // Residuals in px, camera ones divided by sigma_c and projector ones by
  // sigma_p (each device's own noise, from a first unweighted pass).
  double sigma_c = 1, sigma_p = 1;
  auto model = [&](const Eigen::VectorXd& x, CameraProjectorCalibration& out,
                   std::vector<Eigen::Isometry3d>& board_poses) {
    out = c;
    out.R = detail::poseDelta(x.head<6>()).linear() * c.R;
    out.t = c.t + x.segment<3>(3);
    board_poses.resize(views.size());
    for (std::size_t i = 0; i < views.size(); ++i) {
      const Eigen::VectorXd d = x.segment(6 + 6 * i, 6);
      board_poses[i] = poses[i];
      board_poses[i].linear() = poses[i].linear() * detail::poseDelta(d).linear();
      board_poses[i].translation() = poses[i].translation() + d.segment<3>(3);
    }
  };
  const detail::ResidualFunction f = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    CameraProjectorCalibration current;
    std::vector<Eigen::Isometry3d> board_poses;
    model(x, current, board_poses);
    int row = 0;
    for (std::size_t i = 0; i < views.size(); ++i)
      for (std::size_t k = 0; k < views[i].corner_ids.size(); ++k, row += 4) {
        const Eigen::Vector3d X = board_poses[i] * cornerOf(board, views[i].corner_ids[k]);
        const Eigen::Vector2d qc = current.camera.project(X);
        const Eigen::Vector2d qp = current.projector.project(current.R * X + current.t);
        r.segment<2>(row) =
            (qc - Eigen::Vector2d(views[i].camera_px[k].x, views[i].camera_px[k].y)) / sigma_c;
        r.segment<2>(row + 2) =
            (qp - Eigen::Vector2d(views[i].projector_px[k].x, views[i].projector_px[k].y)) /
            sigma_p;
      }
  };
  detail::LeastSquaresSolution s;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(params);
  double camera_rms = 0, projector_rms = 0;
  for (int pass = 0; pass < 2; ++pass) {
    s = detail::solveLeastSquares(f, x, values);
    x = s.x;
    double sc = 0, sp = 0;
    for (int row = 0; row < values; row += 4) {
      sc += s.residuals.segment<2>(row).squaredNorm() * sigma_c * sigma_c;
      sp += s.residuals.segment<2>(row + 2).squaredNorm() * sigma_p * sigma_p;
    }
    camera_rms = std::sqrt(sc / corners);
    projector_rms = std::sqrt(sp / corners);
    // Per-coordinate sigma, with the degrees of freedom the fit used.
    const double dof = double(values) / double(std::max(values - params, 1));
    sigma_c = std::max(camera_rms / std::sqrt(2.0) * std::sqrt(dof), 1e-4);
    sigma_p = std::max(projector_rms / std::sqrt(2.0) * std::sqrt(dof), 1e-4);
  }
  // Weighted residuals now have unit variance: covariance (J^T J)^-1 (J of
  // the last pass's weights).
  const Eigen::MatrixXd J = detail::numericJacobian(f, x, values, 1e-6);
  const Eigen::MatrixXd cov =
      (J.transpose() * J).ldlt().solve(Eigen::MatrixXd::Identity(params, params));
  ProjectorPoseCorrection out;
  std::vector<Eigen::Isometry3d> board_poses;
  model(x, out.calibration, board_poses);
  for (int q = 0; q < 3; ++q) {
    out.sigma_rotation_deg(q) = std::sqrt(std::max(cov(q, q), 0.0)) * kDeg;
    out.sigma_translation_mm(q) = std::sqrt(std::max(cov(3 + q, 3 + q), 0.0));
  }
  out.rotation_change_deg =
      Eigen::AngleAxisd(out.calibration.R * c.R.transpose()).angle() * kDeg;
  out.translation_change_mm = (out.calibration.t - c.t).norm();
  out.camera_rms_px = camera_rms;
  out.projector_rms_px = projector_rms;
  return out;
}

}  // namespace sl::pipeline
