#include "depth_rectify.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace sl::daemon {

DepthRectifier::DepthRectifier(const pipeline::PinholeModel& camera)
    : width_(camera.width), height_(camera.height) {
  if (width_ < 2 || height_ < 2 || !(camera.fx > 0) || !(camera.fy > 0))
    throw std::invalid_argument("DepthRectifier: camera model without size (2 x 2 px at least) or focal length");
  const std::size_t n = static_cast<std::size_t>(width_) * height_;
  raw_index_.resize(n);
  weight_u_.resize(n);
  weight_v_.resize(n);
  for (int v = 0; v < height_; ++v)
    for (int u = 0; u < width_; ++u) {
      // The rectified camera is the ideal pinhole with the same K.
      const Eigen::Vector2d raw =
          camera.normalizedToPixel({(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy});
      const std::size_t i = static_cast<std::size_t>(v) * width_ + u;
      // Inside the raw image: its pixel centres span [0, width - 1].
      if (!(raw.x() >= 0.0 && raw.y() >= 0.0 && raw.x() <= width_ - 1 && raw.y() <= height_ - 1)) {
        raw_index_[i] = -1;
        continue;
      }
      const int u0 = std::min(static_cast<int>(raw.x()), width_ - 2);
      const int v0 = std::min(static_cast<int>(raw.y()), height_ - 2);
      raw_index_[i] = v0 * width_ + u0;
      weight_u_[i] = static_cast<float>(raw.x() - u0);
      weight_v_[i] = static_cast<float>(raw.y() - v0);
    }
}

void DepthRectifier::rectify(const std::vector<float>& raw, std::vector<float>& rectified) const {
  const std::size_t n = static_cast<std::size_t>(width_) * height_;
  if (raw.size() != n)
    throw std::invalid_argument("DepthRectifier: depth image of " + std::to_string(raw.size()) +
                                " pixels for a " + std::to_string(width_) + "x" +
                                std::to_string(height_) + " camera");
  rectified.resize(n);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::size_t row = static_cast<std::size_t>(width_);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int32_t k = raw_index_[i];
    if (k < 0) {
      rectified[i] = nan;
      continue;
    }
    const float* z = raw.data() + k;
    const float z00 = z[0], z01 = z[1], z10 = z[row], z11 = z[row + 1];
    const float a = weight_u_[i], b = weight_v_[i];
    // A NaN neighbour makes the sum NaN (whatever its weight) and fails the
    // spread test (comparisons with NaN are false).
    const float value = (1 - b) * ((1 - a) * z00 + a * z01) + b * ((1 - a) * z10 + a * z11);
    const float lo = std::min(std::min(z00, z01), std::min(z10, z11));
    const float hi = std::max(std::max(z00, z01), std::max(z10, z11));
    rectified[i] = hi - lo <= kMaxRelativeSpread * lo ? value : nan;
  }
}

}  // namespace sl::daemon
