#include "plots.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace sl::eval {

namespace {

std::string format(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.3g", v);
  return buffer;
}

void text(cv::Mat& image, const std::string& s, cv::Point at, double scale = 0.5) {
  cv::putText(image, s, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
}

void write(const std::string& path, const cv::Mat& image) {
  if (!cv::imwrite(path, image)) throw std::runtime_error("cannot write " + path);
}

}  // namespace

namespace {

// Colour map of values in [lo, hi] (NaN black), shown at about 720 px wide,
// with a title and a colour bar labelled lo..hi.
void writeMap(const std::string& path, const cv::Mat& values, double lo, double hi,
              const std::string& title, const std::string& unit) {
  cv::Mat scaled(values.size(), CV_8UC1), mask(values.size(), CV_8UC1, cv::Scalar(0));
  for (int r = 0; r < values.rows; ++r)
    for (int c = 0; c < values.cols; ++c) {
      const float v = values.at<float>(r, c);
      if (std::isnan(v)) continue;
      mask.at<std::uint8_t>(r, c) = 255;
      scaled.at<std::uint8_t>(r, c) =
          cv::saturate_cast<std::uint8_t>(255.0 * std::clamp((v - lo) / (hi - lo), 0.0, 1.0));
    }
  cv::Mat coloured;
  cv::applyColorMap(scaled, coloured, cv::COLORMAP_JET);
  cv::Mat heat(values.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  coloured.copyTo(heat, mask);
  // Large images at half size, small crops enlarged (whole pixels) to >= 360 px.
  cv::Mat small;
  if (values.cols > 1000) {
    cv::resize(heat, small, cv::Size(values.cols / 2, values.rows / 2), 0, 0, cv::INTER_AREA);
  } else {
    const int factor = std::max(1, 360 / std::max(std::min(values.cols, values.rows), 1));
    cv::resize(heat, small, cv::Size(values.cols * factor, values.rows * factor), 0, 0,
               cv::INTER_NEAREST);
  }
  const int bar = 170, top = 40;
  const int width = std::max(small.cols + bar, 12 * static_cast<int>(title.size()) + 20);
  cv::Mat canvas(small.rows + top + 20, width, CV_8UC3, cv::Scalar(255, 255, 255));
  small.copyTo(canvas(cv::Rect(0, top, small.cols, small.rows)));
  text(canvas, title, {10, 25}, 0.6);
  for (int y = 0; y < small.rows; ++y) {
    cv::Mat level(1, 1, CV_8UC1, cv::Scalar(255 - 255 * y / std::max(small.rows - 1, 1)));
    cv::Mat c;
    cv::applyColorMap(level, c, cv::COLORMAP_JET);
    cv::line(canvas, {small.cols + 15, top + y}, {small.cols + 40, top + y},
             cv::Scalar(c.at<cv::Vec3b>(0, 0)));
  }
  text(canvas, format(hi) + " " + unit, {small.cols + 45, top + 12});
  text(canvas, format(lo) + " " + unit, {small.cols + 45, top + small.rows});
  write(path, canvas);
}

}  // namespace

void writeHeatMap(const std::string& path, const cv::Mat& values, double max_value,
                  const std::string& title, const std::string& unit) {
  writeMap(path, values, 0.0, max_value, title, unit);
}

void writeSignedMap(const std::string& path, const cv::Mat& values, double limit,
                    const std::string& title, const std::string& unit) {
  writeMap(path, values, -limit, limit, title, unit);
}

void writeLinePlot(const std::string& path, const std::vector<Curve>& curves,
                   const std::string& title, const std::string& x_label,
                   const std::string& y_label) {
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const Curve& c : curves)
    for (std::size_t i = 0; i < c.x.size(); ++i) {
      if (std::isnan(c.y[i])) continue;
      x0 = std::min(x0, c.x[i]), x1 = std::max(x1, c.x[i]);
      y0 = std::min(y0, c.y[i]), y1 = std::max(y1, c.y[i]);
    }
  if (!(x1 > x0)) x0 = 0, x1 = 1;
  if (!(y1 > y0)) y0 -= 1, y1 += 1;
  const double pad = 0.05 * (y1 - y0);
  y0 -= pad, y1 += pad;
  const int width = 1400, height = 600, left = 90, right = 20, top = 50, bottom = 60;
  cv::Mat canvas(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  auto px = [&](double x, double y) {
    return cv::Point(int(left + (x - x0) / (x1 - x0) * (width - left - right)),
                     int(height - bottom - (y - y0) / (y1 - y0) * (height - top - bottom)));
  };
  cv::rectangle(canvas, px(x0, y0), px(x1, y1), cv::Scalar(0, 0, 0));
  for (int k = 0; k <= 5; ++k) {
    const double x = x0 + k * (x1 - x0) / 5, y = y0 + k * (y1 - y0) / 5;
    text(canvas, format(x), px(x, y0) + cv::Point(-15, 20), 0.45);
    text(canvas, format(y), px(x0, y) + cv::Point(-80, 5), 0.45);
    cv::line(canvas, px(x0, y), px(x1, y), cv::Scalar(220, 220, 220));
  }
  text(canvas, title, {left, 30}, 0.6);
  text(canvas, x_label, {width / 2 - 60, height - 15});
  text(canvas, y_label, {5, top - 10}, 0.45);
  int legend_y = top + 20;
  for (const Curve& c : curves) {
    for (std::size_t i = 1; i < c.x.size(); ++i)
      if (!std::isnan(c.y[i - 1]) && !std::isnan(c.y[i]))
        cv::line(canvas, px(c.x[i - 1], c.y[i - 1]), px(c.x[i], c.y[i]), c.colour, 1, cv::LINE_AA);
    cv::line(canvas, {width - 300, legend_y - 5}, {width - 270, legend_y - 5}, c.colour, 2);
    text(canvas, c.label, {width - 260, legend_y});
    legend_y += 22;
  }
  write(path, canvas);
}

}  // namespace sl::eval
