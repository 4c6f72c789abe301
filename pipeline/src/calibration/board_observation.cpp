// Checkerboard corners on the shading image and their projector coordinates
// by local homographies.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sl/pipeline/calibration.h"

namespace sl::pipeline {

cv::Point3f Checkerboard::corner(int id) const {
  const int row = id / cols, col = id % cols;
  return {static_cast<float>(col * square_mm), static_cast<float>(row * square_mm), 0.0f};
}

void Checkerboard::validate() const {
  if (cols < 2) throw std::invalid_argument("checkerboard: cols (inner corners) must be >= 2");
  if (rows < 2) throw std::invalid_argument("checkerboard: rows (inner corners) must be >= 2");
  if (cols == rows)
    throw std::invalid_argument(
        "checkerboard: cols and rows must differ (a square board's orientation is ambiguous)");
  if (!(square_mm > 0 && std::isfinite(square_mm)))
    throw std::invalid_argument("checkerboard: square_mm must be > 0");
}

namespace {

// The shading image as CV_32FC1 (values unchanged) and as CV_8UC1 stretched
// over its value range, for the detector.
void shadingImages(const cv::Mat& shading, cv::Mat& as_float, cv::Mat& as_8bit) {
  if (shading.empty() || shading.channels() != 1)
    throw std::invalid_argument("detectCheckerboardCorners: shading must be single-channel");
  shading.convertTo(as_float, CV_32F);
  cv::patchNaNs(as_float, 0.0);
  double low = 0, high = 0;
  cv::minMaxLoc(as_float, &low, &high);
  const double scale = high > low ? 255.0 / (high - low) : 1.0;
  as_float.convertTo(as_8bit, CV_8U, scale, -low * scale);
}

}  // namespace

std::optional<std::vector<cv::Point2f>> detectCheckerboardCorners(
    const cv::Mat& shading, const Checkerboard& board, const CornerDetectionOptions& options) {
  board.validate();
  cv::Mat as_float, as_8bit;
  shadingImages(shading, as_float, as_8bit);
  const cv::Size pattern(board.cols, board.rows);
  std::vector<cv::Point2f> corners;
  bool found = cv::findChessboardCorners(
      as_8bit, pattern, corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
  if (!found) {
    // The sector-based detector copes with stronger blur and perspective.
    found = cv::findChessboardCornersSB(as_8bit, pattern, corners,
                                        cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_EXHAUSTIVE);
  }
  if (!found || static_cast<int>(corners.size()) != board.cornerCount()) return std::nullopt;
  const int radius = std::max(1, options.subpixel_radius_px);
  cv::cornerSubPix(as_float, corners, cv::Size(radius, radius), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  const cv::Point2f first = corners.front(), last = corners.back();
  if (first.x + first.y > last.x + last.y) std::reverse(corners.begin(), corners.end());
  return corners;
}

std::optional<cv::Point2f> projectorPointByLocalHomography(const ProjectorMaps& maps,
                                                           cv::Point2f camera_px,
                                                           const LocalHomographyOptions& options) {
  if (maps.up.type() != CV_32FC1 || maps.vp.type() != CV_32FC1 || maps.up.size() != maps.vp.size())
    throw std::invalid_argument(
        "projectorPointByLocalHomography: up and vp must be CV_32FC1 of one size");
  const int radius = std::max(1, options.window_radius_px);
  const int cx = static_cast<int>(std::lround(camera_px.x));
  const int cy = static_cast<int>(std::lround(camera_px.y));
  const int x0 = std::max(cx - radius, 0), x1 = std::min(cx + radius, maps.up.cols - 1);
  const int y0 = std::max(cy - radius, 0), y1 = std::min(cy + radius, maps.up.rows - 1);
  // Camera coordinates relative to the corner keep the fit well conditioned.
  std::vector<cv::Point2f> camera, projector;
  for (int y = y0; y <= y1; ++y) {
    const float* up = maps.up.ptr<float>(y);
    const float* vp = maps.vp.ptr<float>(y);
    for (int x = x0; x <= x1; ++x) {
      if (!std::isfinite(up[x]) || !std::isfinite(vp[x])) continue;
      camera.emplace_back(float(x) - camera_px.x, float(y) - camera_px.y);
      projector.emplace_back(up[x], vp[x]);
    }
  }
  const int min_pixels = std::max(options.min_valid_pixels, 4);
  if (static_cast<int>(camera.size()) < min_pixels) return std::nullopt;
  cv::Mat inliers;
  const cv::Mat H = cv::findHomography(camera, projector, cv::RANSAC,
                                       options.inlier_threshold_px, inliers, 2000, 0.999);
  if (H.empty() || cv::countNonZero(inliers) < min_pixels) return std::nullopt;
  // The corner is the origin of the camera coordinates: H * (0, 0, 1).
  const double w = H.at<double>(2, 2);
  if (!(std::abs(w) > 1e-12)) return std::nullopt;
  const cv::Point2f result(static_cast<float>(H.at<double>(0, 2) / w),
                           static_cast<float>(H.at<double>(1, 2) / w));
  if (!std::isfinite(result.x) || !std::isfinite(result.y)) return std::nullopt;
  return result;
}

BoardViewResult observeBoard(const cv::Mat& shading, const ProjectorMaps& maps,
                             const Checkerboard& board, const std::string& label,
                             const CornerDetectionOptions& corner_options,
                             const LocalHomographyOptions& homography_options) {
  BoardViewResult result;
  const auto corners = detectCheckerboardCorners(shading, board, corner_options);
  if (!corners) {
    result.error = label + ": checkerboard " + std::to_string(board.cols) + "x" +
                   std::to_string(board.rows) + " not found in the shading image";
    return result;
  }
  BoardView view;
  view.label = label;
  for (int id = 0; id < board.cornerCount(); ++id) {
    const cv::Point2f c = (*corners)[id];
    const auto p = projectorPointByLocalHomography(maps, c, homography_options);
    if (!p) {
      ++view.corners_dropped;
      continue;
    }
    view.corner_ids.push_back(id);
    view.camera_px.push_back(c);
    view.projector_px.push_back(*p);
  }
  if (2 * static_cast<int>(view.corner_ids.size()) < board.cornerCount()) {
    result.error = label + ": only " + std::to_string(view.corner_ids.size()) + " of " +
                   std::to_string(board.cornerCount()) +
                   " corners have a projector coordinate (too few decoded pixels around them)";
    return result;
  }
  result.view = std::move(view);
  return result;
}

}  // namespace sl::pipeline
