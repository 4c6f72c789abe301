// The depth image on the rectified pixel grid of its camera, as ROS's
// depth_image_proc expects it: a pixel (u, v) of depth z stands for the point
// ((u - cx) z / fx, (v - cy) z / fy, z) of the camera's ideal pinhole model
// (the camera's K without its lens distortion; camera_info with D = 0 and
// P = [K | 0]). Private to daemon/.
#pragma once

#include <cstdint>
#include <vector>

#include "sl/pipeline/camera_model.h"

namespace sl::daemon {

// Resamples depth images (metres, NaN where invalid) from a camera's raw,
// distorted pixel grid onto its rectified grid (same size and K, no
// distortion). Each rectified pixel takes the depth of the raw image at the
// (sub-pixel) place its ray meets the raw image, bilinearly from the 4 raw
// pixels around it; NaN when one of them is invalid, the place is outside the
// image, or their depths spread by more than kMaxRelativeSpread of the
// nearest (a depth edge: no invented in-between surface).
// Immutable after construction: thread-safe.
class DepthRectifier {
 public:
  static constexpr float kMaxRelativeSpread = 0.01f;

  explicit DepthRectifier(const pipeline::PinholeModel& camera);

  int width() const { return width_; }
  int height() const { return height_; }
  // `raw`: width() x height() depths, row-major; `rectified` is resized to
  // the same size. Throws std::invalid_argument on a size mismatch.
  void rectify(const std::vector<float>& raw, std::vector<float>& rectified) const;

 private:
  int width_ = 0, height_ = 0;
  // Per rectified pixel, where its ray meets the raw image: the index of the
  // raw pixel up and left of that place (-1: outside the raw image) and the
  // bilinear weights of the pixels right of and below it.
  std::vector<std::int32_t> raw_index_;
  std::vector<float> weight_u_, weight_v_;
};

}  // namespace sl::daemon
