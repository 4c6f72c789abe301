#include "residual_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

namespace sl::tools {

namespace {

constexpr int kSize = 720;     // image side, px
constexpr int kMargin = 60;    // around the plot area
constexpr int kLegendWidth = 180;

cv::Scalar poseColour(std::size_t i) {
  // Distinct hues, BGR.
  static const cv::Scalar kColours[] = {
      {180, 119, 31}, {14, 127, 255}, {44, 160, 44},  {40, 39, 214},  {189, 103, 148},
      {75, 86, 140},  {194, 119, 227}, {127, 127, 127}, {34, 189, 188}, {207, 190, 23}};
  return kColours[i % (sizeof kColours / sizeof kColours[0])];
}

}  // namespace

cv::Mat plotResiduals(const pipeline::CalibrationReport& report, bool projector,
                      double warning_px, const std::string& title) {
  double extent = warning_px * 1.1;
  for (const auto& c : report.corners) {
    const cv::Point2f r = projector ? c.projector_px : c.camera_px;
    extent = std::max({extent, std::abs(double(r.x)) * 1.05, std::abs(double(r.y)) * 1.05});
  }
  cv::Mat image(kSize, kSize + kLegendWidth, CV_8UC3, cv::Scalar(255, 255, 255));
  const int side = kSize - 2 * kMargin;
  const cv::Point centre(kMargin + side / 2, kMargin + side / 2);
  const double scale = side / (2.0 * extent);  // image px per residual px
  auto toImage = [&](double x, double y) {
    return cv::Point(static_cast<int>(std::lround(centre.x + x * scale)),
                     static_cast<int>(std::lround(centre.y + y * scale)));
  };
  const auto font = cv::FONT_HERSHEY_SIMPLEX;
  cv::rectangle(image, {kMargin, kMargin}, {kMargin + side, kMargin + side}, {0, 0, 0}, 1);
  cv::line(image, {kMargin, centre.y}, {kMargin + side, centre.y}, {200, 200, 200}, 1);
  cv::line(image, {centre.x, kMargin}, {centre.x, kMargin + side}, {200, 200, 200}, 1);
  // Dashed circle at the warning threshold.
  const int radius = static_cast<int>(std::lround(warning_px * scale));
  for (int degrees = 0; degrees < 360; degrees += 10)
    cv::ellipse(image, centre, {radius, radius}, 0, degrees, degrees + 5, {0, 0, 200}, 1,
                cv::LINE_AA);
  char text[128];
  std::snprintf(text, sizeof text, "%.2f px", warning_px);
  cv::putText(image, text, centre + cv::Point(radius + 4, -4), font, 0.4, {0, 0, 200}, 1,
              cv::LINE_AA);
  // Axis labels: the range in residual px.
  std::snprintf(text, sizeof text, "-%.2f", extent);
  cv::putText(image, text, {kMargin - 10, kMargin + side + 18}, font, 0.4, {0, 0, 0}, 1,
              cv::LINE_AA);
  std::snprintf(text, sizeof text, "+%.2f px (x right, y down)", extent);
  cv::putText(image, text, {kMargin + side - 150, kMargin + side + 18}, font, 0.4, {0, 0, 0}, 1,
              cv::LINE_AA);
  cv::putText(image, title, {kMargin, kMargin - 20}, font, 0.6, {0, 0, 0}, 1, cv::LINE_AA);

  for (const auto& c : report.corners) {
    const cv::Point2f r = projector ? c.projector_px : c.camera_px;
    cv::circle(image, toImage(r.x, r.y), 2, poseColour(c.pose), cv::FILLED, cv::LINE_AA);
  }
  for (std::size_t i = 0; i < report.poses.size(); ++i) {
    const auto& p = report.poses[i];
    const int y = kMargin + 10 + static_cast<int>(i) * 20;
    cv::circle(image, {kSize + 5, y - 4}, 5, poseColour(i), cv::FILLED, cv::LINE_AA);
    std::snprintf(text, sizeof text, "%s %.3f", p.label.c_str(),
                  projector ? p.projector_rms_px : p.camera_rms_px);
    cv::putText(image, text, {kSize + 16, y}, font, 0.45, {0, 0, 0}, 1, cv::LINE_AA);
  }
  return image;
}

}  // namespace sl::tools
