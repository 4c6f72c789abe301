// Minimal PNG plots drawn with OpenCV (no plotting library): a heat map with
// a colour bar and a line plot with axes. Private to sl_eval.
#pragma once

#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

namespace sl::eval {

// values: CV_32FC1, NaN = no data (drawn black). Colour scale [0, max_value].
void writeHeatMap(const std::string& path, const cv::Mat& values, double max_value,
                  const std::string& title, const std::string& unit);

// Signed values (CV_32FC1, NaN = no data) on the scale [-limit, limit].
void writeSignedMap(const std::string& path, const cv::Mat& values, double limit,
                    const std::string& title, const std::string& unit);

struct Curve {
  std::string label;
  std::vector<double> x, y;  // NaN y = gap
  cv::Scalar colour;         // BGR
};

void writeLinePlot(const std::string& path, const std::vector<Curve>& curves,
                   const std::string& title, const std::string& x_label,
                   const std::string& y_label);

}  // namespace sl::eval
