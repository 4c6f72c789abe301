// Motion compensation for linear motion (paper section 2.4.2, eq. 9-11).
//
// When the sensor moves along one image axis, perpendicular to the fringes,
// the projector coordinate seen by a scene point does not change, only its
// position in the image. Every image of a sequence is registered to a
// reference image of the same sequence by phase correlation (not by
// interpolating between frames, so non-uniform motion is handled), and
// resampled so that it aligns with the reference.
//
// The registration is one-dimensional: the cross-power spectrum (eq. 10) is
// summed over the frequencies across the motion axis (its inverse transform
// is the correlation on the line of zero shift across the axis) and whitened
// by the square root of its magnitude; the frequency zero along the motion
// axis (and +-1 with the Hann window) is left out, because the projected
// fringes do not move with the scene and would pull the peak (see
// motion_compensation.cpp).
#pragma once

#include <memory>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct MotionCompensationOptions {
  enum class Axis { kX, kY } axis = Axis::kX;  // image axis along which the scene moves
  int reference_frame = -1;    // index in the sequence; -1 = the middle frame
  int subsample = 2;           // register on images downsampled by this factor (1, 2, 4)
  bool window = true;          // Hann window against edge effects
  double max_shift_px = 200;   // the shift is searched within +-max_shift_px
};

struct MotionEstimate {
  // Per camera, per frame: position of the frame's content relative to the
  // reference frame along the axis (px, full resolution). The reference is 0.
  std::vector<std::vector<double>> shifts_px;
  bool all_within_limit = true;
};

// Thread-compatible; holds only its options and a cached window.
class MotionCompensator {
 public:
  explicit MotionCompensator(MotionCompensationOptions options);

  // Shift of `moving`'s content relative to `reference` along the axis (px).
  // Both images the same size, CV_8UC1 / CV_16UC1 / CV_32FC1. A correlation
  // whose maximum lies on the edge of the +-max_shift_px search range has no
  // peak within it: the result is then beyond max_shift_px (by the sign).
  double estimateShift(const cv::Mat& reference, const cv::Mat& moving) const;

  // A new image set whose frames are aligned with the reference frame (by
  // sub-pixel resampling along the axis; pixels whose source lies even partly
  // outside the frame are 0, so the decoder marks them invalid), stamped with
  // the reference frame's time. Throws std::invalid_argument on an empty set or a bad reference.
  std::shared_ptr<const ImageSet> compensate(const ImageSet& set,
                                             MotionEstimate* estimate = nullptr) const;

  const MotionCompensationOptions& options() const { return options_; }

 private:
  MotionCompensationOptions options_;
  mutable cv::Mat window_;  // cached Hann window for the last size (thread-compatible)
};

}  // namespace sl::pipeline
