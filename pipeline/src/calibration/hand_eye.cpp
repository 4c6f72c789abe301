#include "sl/pipeline/hand_eye.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

#include "least_squares.h"

namespace sl::pipeline {

namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

std::string format(const char* f, double a, double b = 0, double c = 0, double d = 0) {
  char text[256];
  std::snprintf(text, sizeof text, f, a, b, c, d);
  return text;
}

// Rotation R0 exp(w) and translation t0 + dt from x = (w, dt).
Eigen::Isometry3d perturbed(const Eigen::Isometry3d& pose,
                            const Eigen::Ref<const Eigen::VectorXd>& x) {
  Eigen::Isometry3d out = pose;
  out.linear() = pose.linear() * detail::poseDelta(x).linear();
  out.translation() = pose.translation() + x.segment<3>(3);
  return out;
}

}  // namespace

std::vector<Eigen::Vector3d> triangulateBoardCorners(const CameraProjectorCalibration& c,
                                                     const BoardView& view) {
  if (view.camera_px.size() != view.corner_ids.size() ||
      view.projector_px.size() != view.corner_ids.size())
    throw std::invalid_argument("board view '" + view.label + "': inconsistent corner lists");
  const int axis = std::abs(c.t.x()) >= std::abs(c.t.y()) ? 0 : 1;
  std::vector<Eigen::Vector3d> points;
  points.reserve(view.corner_ids.size());
  for (std::size_t k = 0; k < view.corner_ids.size(); ++k) {
    const Eigen::Vector2d xc =
        c.camera.pixelToNormalized({view.camera_px[k].x, view.camera_px[k].y});
    const double p =
        c.projector.pixelToNormalized({view.projector_px[k].x, view.projector_px[k].y})[axis];
    const Eigen::Vector3d ray(xc.x(), xc.y(), 1.0);
    // X = s ray with (R X + t)[axis] = p (R X + t).z
    const double s =
        (p * c.t.z() - c.t[axis]) / (c.R.row(axis).dot(ray) - p * c.R.row(2).dot(ray));
    points.push_back(s * ray);
  }
  return points;
}

Eigen::Isometry3d fitBoardPose(const Checkerboard& board, const std::vector<int>& corner_ids,
                               const std::vector<Eigen::Vector3d>& points, double* rms_mm) {
  if (corner_ids.size() != points.size() || points.size() < 3)
    throw std::invalid_argument("fitBoardPose: needs >= 3 corners with one point each");
  Eigen::Matrix3Xd from(3, points.size()), to(3, points.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    const cv::Point3f b = board.corner(corner_ids[k]);
    from.col(k) = Eigen::Vector3d(b.x, b.y, b.z);
    to.col(k) = points[k];
  }
  Eigen::Isometry3d pose(Eigen::umeyama(from, to, false));
  if (rms_mm) {
    const Eigen::Matrix3Xd d = (pose * from) - to;
    *rms_mm = std::sqrt(d.colwise().squaredNorm().sum() / double(points.size()));
  }
  return pose;
}

HandEyeResult calibrateHandEye(const std::vector<HandEyeView>& views, const Checkerboard& board,
                               HandEyeSetup setup, const HandEyeOptions& options) {
  board.validate();
  if (views.size() < 3)
    throw std::invalid_argument("hand-eye calibration needs at least 3 views, got " +
                                std::to_string(views.size()));
  const bool in_hand = setup == HandEyeSetup::kEyeInHand;
  std::vector<Eigen::Isometry3d> A;  // base_from_gripper or gripper_from_base
  std::vector<cv::Mat> R_robot, t_robot, R_target, t_target;
  int values = 0;
  for (const HandEyeView& v : views) {
    if (v.corner_ids.size() != v.points_mm.size() || v.points_mm.size() < 4)
      throw std::invalid_argument("hand-eye view '" + v.label +
                                  "': needs >= 4 corners with one point each");
    for (int id : v.corner_ids)
      if (id < 0 || id >= board.cornerCount())
        throw std::invalid_argument("hand-eye view '" + v.label + "': corner id out of range");
    A.push_back(in_hand ? v.base_from_gripper : v.base_from_gripper.inverse());
    const Eigen::Isometry3d target = fitBoardPose(board, v.corner_ids, v.points_mm);
    cv::Mat Rr(3, 3, CV_64F), tr(3, 1, CV_64F), Rt(3, 3, CV_64F), tt(3, 1, CV_64F);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        Rr.at<double>(r, c) = A.back().linear()(r, c);
        Rt.at<double>(r, c) = target.linear()(r, c);
      }
      tr.at<double>(r) = A.back().translation()(r);
      tt.at<double>(r) = target.translation()(r);
    }
    R_robot.push_back(Rr);
    t_robot.push_back(tr);
    R_target.push_back(Rt);
    t_target.push_back(tt);
    values += 3 * static_cast<int>(v.points_mm.size());
  }
  // Rotations about at least two axes: the relative motions' axes must not all
  // be parallel (else the mount's translation along them is undetermined).
  double largest_axis_angle = 0;
  std::vector<Eigen::Vector3d> axes;
  for (std::size_t i = 1; i < A.size(); ++i) {
    const Eigen::AngleAxisd motion((A[0].inverse() * A[i]).linear());
    if (motion.angle() > 2.0 / kDeg) axes.push_back(motion.axis());
  }
  for (std::size_t i = 0; i < axes.size(); ++i)
    for (std::size_t j = i + 1; j < axes.size(); ++j)
      largest_axis_angle =
          std::max(largest_axis_angle, std::acos(std::min(1.0, std::abs(axes[i].dot(axes[j])))));
  if (largest_axis_angle < 5.0 / kDeg)
    throw std::invalid_argument(
        "hand-eye calibration: the robot poses rotate about one axis only (or by less than 2 "
        "deg): add poses that tilt the flange about two different axes");

  HandEyeResult result;
  cv::Mat R_mount, t_mount;
  cv::calibrateHandEye(R_robot, t_robot, R_target, t_target, R_mount, t_mount,
                       cv::CALIB_HAND_EYE_TSAI);
  Eigen::Isometry3d X0 = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) X0.linear()(r, c) = R_mount.at<double>(r, c);
    X0.translation()(r) = t_mount.at<double>(r);
  }
  result.initial_mount = X0;
  // Y's start: the mean over the views of A_i X0 T_i (rotation by SVD).
  Eigen::Matrix3d rotation_sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d translation_sum = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < views.size(); ++i) {
    const Eigen::Isometry3d y =
        A[i] * X0 * fitBoardPose(board, views[i].corner_ids, views[i].points_mm);
    rotation_sum += y.linear();
    translation_sum += y.translation();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(rotation_sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d Ry = svd.matrixU() * svd.matrixV().transpose();
  if (Ry.determinant() < 0) {
    Eigen::Matrix3d U = svd.matrixU();
    U.col(2) *= -1;
    Ry = U * svd.matrixV().transpose();
  }
  Eigen::Isometry3d Y0 = Eigen::Isometry3d::Identity();
  Y0.linear() = Ry;
  Y0.translation() = translation_sum / double(views.size());

  // Board corners in the board frame, per view.
  std::vector<std::vector<Eigen::Vector3d>> B(views.size());
  for (std::size_t i = 0; i < views.size(); ++i)
    for (int id : views[i].corner_ids) {
      const cv::Point3f b = board.corner(id);
      B[i].emplace_back(b.x, b.y, b.z);
    }
  // Residuals of every view but `skip` (none: -1).
  std::size_t skip = views.size();
  const detail::ResidualFunction f = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    const Eigen::Isometry3d X = perturbed(X0, x.head<6>());
    const Eigen::Isometry3d Y = perturbed(Y0, x.tail<6>());
    int row = 0;
    for (std::size_t i = 0; i < views.size(); ++i) {
      if (i == skip) continue;
      const Eigen::Isometry3d AX = A[i] * X;
      for (std::size_t k = 0; k < B[i].size(); ++k, row += 3)
        r.segment<3>(row) = AX * views[i].points_mm[k] - Y * B[i][k];
    }
  };
  const detail::LeastSquaresSolution s =
      detail::solveLeastSquares(f, Eigen::VectorXd::Zero(12), values);
  result.mount = perturbed(X0, s.x.head<6>());
  result.target = perturbed(Y0, s.x.tail<6>());

  // Residuals per view.
  double total = 0;
  int row = 0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    double sum = 0;
    for (std::size_t k = 0; k < B[i].size(); ++k, row += 3) sum += s.residuals.segment<3>(row).squaredNorm();
    total += sum;
    result.view_rms_mm.push_back(std::sqrt(sum / double(B[i].size())));
  }
  result.rms_mm = std::sqrt(total / (values / 3.0));

  // Covariance: independent residuals, and clustered by view (sandwich).
  const Eigen::MatrixXd independent = detail::covarianceOf(s);
  const Eigen::MatrixXd JtJ = s.jacobian.transpose() * s.jacobian;
  const Eigen::MatrixXd bread = JtJ.ldlt().solve(Eigen::MatrixXd::Identity(12, 12));
  Eigen::MatrixXd meat = Eigen::MatrixXd::Zero(12, 12);
  row = 0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    const int n = 3 * static_cast<int>(B[i].size());
    const Eigen::VectorXd g =
        s.jacobian.middleRows(row, n).transpose() * s.residuals.segment(row, n);
    meat += g * g.transpose();
    row += n;
  }
  const double small_sample = double(views.size()) / double(views.size() - 1);
  const Eigen::MatrixXd clustered = small_sample * bread * meat * bread;
  // Leave-one-view-out jackknife of the mount: the sandwich above is biased
  // low with few views when each view carries its own error (a robot pose
  // error moves all of a view's corners alike); the jackknife is not as much.
  Eigen::Matrix<double, 6, 1> jackknife = Eigen::Matrix<double, 6, 1>::Zero();
  if (views.size() >= 4) {
    std::vector<Eigen::Matrix<double, 6, 1>> estimates;
    for (std::size_t i = 0; i < views.size(); ++i) {
      skip = i;
      const int n = values - 3 * static_cast<int>(B[i].size());
      estimates.push_back(detail::solveLeastSquares(f, s.x, n).x.head<6>());
    }
    skip = views.size();
    Eigen::Matrix<double, 6, 1> mean = Eigen::Matrix<double, 6, 1>::Zero();
    for (const auto& e : estimates) mean += e;
    mean /= double(estimates.size());
    for (const auto& e : estimates) jackknife += (e - mean).cwiseAbs2();
    jackknife *= double(views.size() - 1) / double(views.size());
  }
  for (int q = 0; q < 6; ++q) {
    const double variance = std::max({independent(q, q), clustered(q, q), jackknife(q)});
    (q < 3 ? result.sigma_rotation_deg(q) : result.sigma_translation_mm(q - 3)) =
        std::sqrt(std::max(variance, 0.0)) * (q < 3 ? kDeg : 1.0);
  }
  result.covariance = independent.topLeftCorner<6, 6>();
  for (int q = 0; q < 6; ++q) {
    const double scale = std::sqrt(std::max({clustered(q, q), independent(q, q), jackknife(q)}) /
                                   std::max(independent(q, q), 1e-300));
    result.covariance.row(q) *= scale;
    result.covariance.col(q) *= scale;
  }

  // Advice.
  std::vector<double> sorted = result.view_rms_mm;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];
  for (std::size_t i = 0; i < views.size(); ++i)
    if (result.view_rms_mm[i] > options.outlier_view_factor * median)
      result.advice.push_back("view " + views[i].label + " fits " +
                              format("%.3f mm RMS against a median of %.3f mm", result.view_rms_mm[i],
                                     median) +
                              ": check its robot pose (order of the poses file, the robot at rest "
                              "while scanning) or drop it");
  if (views.size() < 10)
    result.advice.push_back(std::to_string(views.size()) +
                            " views: 10 or more, spread over the workspace, give a steadier result");
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> rotation(
      result.covariance.topLeftCorner<3, 3>());
  const double worst_rotation = std::sqrt(std::max(rotation.eigenvalues()(2), 0.0)) * kDeg;
  if (worst_rotation > options.max_sigma_rotation_deg) {
    // The least determined rotation axis, in the robot flange's frame (eye-in-
    // hand) or the base frame (eye-to-hand).
    const Eigen::Vector3d axis = result.mount.linear() * rotation.eigenvectors().col(2);
    result.advice.push_back(
        format("the mount's rotation is least determined about [%.2f %.2f %.2f] (1-sigma %.4f "
               "deg)",
               axis.x(), axis.y(), axis.z(), worst_rotation) +
        (in_hand ? " in the flange frame" : " in the base frame") +
        ": add poses that tilt the flange about that axis by 20-40 deg");
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> translation(
      result.covariance.bottomRightCorner<3, 3>());
  const double worst_translation = std::sqrt(std::max(translation.eigenvalues()(2), 0.0));
  if (worst_translation > options.max_sigma_translation_mm) {
    const Eigen::Vector3d axis = translation.eigenvectors().col(2);
    result.advice.push_back(
        format("the mount's translation is least determined along [%.2f %.2f %.2f] (1-sigma %.3f "
               "mm): add poses with larger rotations about axes across that direction",
               axis.x(), axis.y(), axis.z(), worst_translation));
  }
  return result;
}

}  // namespace sl::pipeline
