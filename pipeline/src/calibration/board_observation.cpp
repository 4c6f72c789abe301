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
  // Coarse detection on a half-size image above 1000 px width (several times
  // faster for megapixel cameras), refined at full resolution below. Pixel
  // centres: full x = 2 * half x + 0.5.
  const bool half = as_8bit.cols > 1000;
  cv::Mat detection_image;
  if (half)
    cv::pyrDown(as_8bit, detection_image);
  else
    detection_image = as_8bit;
  std::vector<cv::Point2f> corners;
  bool found = cv::findChessboardCorners(
      detection_image, pattern, corners,
      cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK);
  if (!found) {
    // The sector-based detector copes with stronger blur and perspective.
    found = cv::findChessboardCornersSB(detection_image, pattern, corners,
                                        cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_EXHAUSTIVE);
  }
  if (!found || static_cast<int>(corners.size()) != board.cornerCount()) return std::nullopt;
  if (half)
    for (cv::Point2f& c : corners) c = c * 2.0f + cv::Point2f(0.5f, 0.5f);
  const int radius = std::max(1, options.subpixel_radius_px);
  if (options.presmooth_sigma_px > 0)
    cv::GaussianBlur(as_float, as_float, cv::Size(), options.presmooth_sigma_px);
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
  // Pixels of weak modulation (the dark squares) decode with proportionally
  // more phase noise: keep those at or above min_relative_modulation times
  // the window's strongest (its 90th percentile, robust to hot pixels).
  float min_modulation = 0.0f;
  const bool use_modulation = options.min_relative_modulation > 0 &&
                              maps.modulation.type() == CV_32FC1 &&
                              maps.modulation.size() == maps.up.size();
  if (use_modulation) {
    std::vector<float> values;
    for (int y = y0; y <= y1; ++y) {
      const float* b = maps.modulation.ptr<float>(y);
      for (int x = x0; x <= x1; ++x)
        if (std::isfinite(b[x])) values.push_back(b[x]);
    }
    if (!values.empty()) {
      const auto p90 = values.begin() + static_cast<std::ptrdiff_t>(values.size() * 9 / 10);
      std::nth_element(values.begin(), p90, values.end());
      min_modulation = static_cast<float>(options.min_relative_modulation * *p90);
    }
  }
  std::vector<cv::Point2f> camera, projector;
  for (int y = y0; y <= y1; ++y) {
    const float* up = maps.up.ptr<float>(y);
    const float* vp = maps.vp.ptr<float>(y);
    const float* b = use_modulation ? maps.modulation.ptr<float>(y) : nullptr;
    for (int x = x0; x <= x1; ++x) {
      if (!std::isfinite(up[x]) || !std::isfinite(vp[x])) continue;
      if (b && !(b[x] >= min_modulation)) continue;
      camera.emplace_back(float(x) - camera_px.x, float(y) - camera_px.y);
      projector.emplace_back(up[x], vp[x]);
    }
  }
  const int min_pixels = std::max(options.min_valid_pixels, 4);
  if (static_cast<int>(camera.size()) < min_pixels) return std::nullopt;
  // Least squares (OpenCV's DLT + Levenberg-Marquardt refinement), then
  // trimming: residuals above outlier_factor times the median residual (but
  // at least min_outlier_px) are dropped and the fit repeated. Unlike a
  // RANSAC consensus set, the trimmed set is not biased towards a model drawn
  // from a few noisy points when the decoding noise exceeds the threshold.
  std::vector<cv::Point2f> mapped;
  std::vector<float> residual(camera.size());
  cv::Mat H;
  for (int round = 0; round < 4; ++round) {
    H = cv::findHomography(camera, projector, 0);
    if (H.empty()) return std::nullopt;
    cv::perspectiveTransform(camera, mapped, H);
    residual.resize(camera.size());
    for (std::size_t i = 0; i < camera.size(); ++i)
      residual[i] = static_cast<float>(cv::norm(mapped[i] - projector[i]));
    std::vector<float> sorted = residual;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double limit =
        std::max(options.outlier_factor * sorted[sorted.size() / 2], options.min_outlier_px);
    std::size_t kept = 0;
    for (std::size_t i = 0; i < camera.size(); ++i) {
      if (residual[i] > limit) continue;
      camera[kept] = camera[i];
      projector[kept] = projector[i];
      ++kept;
    }
    if (static_cast<int>(kept) < min_pixels) return std::nullopt;
    if (kept == camera.size()) break;  // nothing trimmed: converged
    camera.resize(kept);
    projector.resize(kept);
  }
  // The corner is the origin of the camera coordinates: H * (0, 0, 1).
  const double w = H.at<double>(2, 2);
  if (!(std::abs(w) > 1e-12)) return std::nullopt;
  const cv::Point2f result(static_cast<float>(H.at<double>(0, 2) / w),
                           static_cast<float>(H.at<double>(1, 2) / w));
  if (!std::isfinite(result.x) || !std::isfinite(result.y)) return std::nullopt;
  return result;
}

cv::Mat meanImage(const std::vector<cv::Mat>& frames) {
  if (frames.empty()) throw std::invalid_argument("meanImage: no frames");
  cv::Mat sum = cv::Mat::zeros(frames.front().size(), CV_32FC1);
  for (const cv::Mat& f : frames) {
    if (f.size() != sum.size() || f.channels() != 1)
      throw std::invalid_argument("meanImage: frames differ in size or are not single-channel");
    cv::accumulate(f, sum);
  }
  return sum / static_cast<double>(frames.size());
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
  result.corners_found = static_cast<int>(corners->size());
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
  result.corners_with_projector = static_cast<int>(view.corner_ids.size());
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
