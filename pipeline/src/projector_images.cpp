#include "sl/pipeline/projector_images.h"

#include <stdexcept>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace sl::pipeline {

cv::Mat diamondDownsample(const cv::Mat& addressed) {
  if (addressed.type() != CV_8UC1 || addressed.cols % 2 != 0)
    throw std::invalid_argument("diamondDownsample: need CV_8UC1 of even width");
  cv::Mat out(addressed.rows, addressed.cols / 2, CV_8UC1);
  for (int r = 0; r < out.rows; ++r) {
    const std::uint8_t* src = addressed.ptr<std::uint8_t>(r) + (r & 1);
    std::uint8_t* dst = out.ptr<std::uint8_t>(r);
    for (int c = 0; c < out.cols; ++c) dst[c] = src[2 * c];
  }
  return out;
}

cv::Mat predistort(const cv::Mat& image, const PinholeModel& projector) {
  if (image.cols != projector.width || image.rows != projector.height)
    throw std::invalid_argument("predistort: image size differs from the projector model");
  cv::Mat map_x(image.size(), CV_32FC1), map_y(image.size(), CV_32FC1);
  for (int v = 0; v < image.rows; ++v) {
    for (int u = 0; u < image.cols; ++u) {
      // Ray of the physical pixel (u, v), then its ideal pinhole pixel.
      const Eigen::Vector2d xn = projector.pixelToNormalized({double(u), double(v)});
      map_x.at<float>(v, u) = static_cast<float>(projector.fx * xn.x() + projector.cx);
      map_y.at<float>(v, u) = static_cast<float>(projector.fy * xn.y() + projector.cy);
    }
  }
  cv::Mat out;
  cv::remap(image, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  return out;
}

std::vector<cv::Mat> packRgb24(const std::vector<cv::Mat>& patterns) {
  std::vector<cv::Mat> out;
  for (std::size_t i = 0; i < patterns.size(); i += 3) {
    const cv::Mat& first = patterns[i];
    if (first.type() != CV_8UC1) throw std::invalid_argument("packRgb24: patterns must be CV_8UC1");
    const cv::Mat black = cv::Mat::zeros(first.size(), CV_8UC1);
    auto at = [&](std::size_t k) -> const cv::Mat& {
      if (k >= patterns.size()) return black;
      if (patterns[k].size() != first.size() || patterns[k].type() != CV_8UC1)
        throw std::invalid_argument("packRgb24: patterns differ in size or type");
      return patterns[k];
    };
    // BGR planes: blue = 3k+2, green = 3k, red = 3k+1.
    const cv::Mat planes[3] = {at(i + 2), at(i), at(i + 1)};
    cv::Mat packed;
    cv::merge(planes, 3, packed);
    out.push_back(packed);
  }
  return out;
}

}  // namespace sl::pipeline
