#include "depth_rectify.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace sl::daemon {

DepthRectifier::DepthRectifier(const pipeline::PinholeModel& camera)
    : width_(camera.width), height_(camera.height) {
  if (width_ <= 0 || height_ <= 0 || !(camera.fx > 0) || !(camera.fy > 0))
    throw std::invalid_argument("DepthRectifier: camera model without size or focal length");
  const std::size_t n = static_cast<std::size_t>(width_) * height_;
  raw_u_.resize(n);
  raw_v_.resize(n);
  for (int v = 0; v < height_; ++v)
    for (int u = 0; u < width_; ++u) {
      // The rectified camera is the ideal pinhole with the same K.
      const Eigen::Vector2d raw =
          camera.normalizedToPixel({(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy});
      const std::size_t i = static_cast<std::size_t>(v) * width_ + u;
      raw_u_[i] = static_cast<float>(raw.x());
      raw_v_[i] = static_cast<float>(raw.y());
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
  for (std::size_t i = 0; i < n; ++i) {
    const float su = raw_u_[i], sv = raw_v_[i];
    // Inside the raw image (its pixel centres span [0, width - 1]).
    if (!(su >= 0.0f && sv >= 0.0f && su <= float(width_ - 1) && sv <= float(height_ - 1))) {
      rectified[i] = nan;
      continue;
    }
    const int u0 = std::min(static_cast<int>(su), width_ - 2 < 0 ? 0 : width_ - 2);
    const int v0 = std::min(static_cast<int>(sv), height_ - 2 < 0 ? 0 : height_ - 2);
    const int u1 = std::min(u0 + 1, width_ - 1), v1 = std::min(v0 + 1, height_ - 1);
    const float a = su - float(u0), b = sv - float(v0);
    const float z00 = raw[static_cast<std::size_t>(v0) * width_ + u0];
    const float z01 = raw[static_cast<std::size_t>(v0) * width_ + u1];
    const float z10 = raw[static_cast<std::size_t>(v1) * width_ + u0];
    const float z11 = raw[static_cast<std::size_t>(v1) * width_ + u1];
    const float lo = std::min(std::min(z00, z01), std::min(z10, z11));
    const float hi = std::max(std::max(z00, z01), std::max(z10, z11));
    // NaN compares false: any invalid neighbour fails this test.
    if (!(std::isfinite(z00) && std::isfinite(z01) && std::isfinite(z10) && std::isfinite(z11)) ||
        !(hi - lo <= kMaxRelativeSpread * lo)) {
      rectified[i] = nan;
      continue;
    }
    rectified[i] = (1 - b) * ((1 - a) * z00 + a * z01) + b * ((1 - a) * z10 + a * z11);
  }
}

}  // namespace sl::daemon
