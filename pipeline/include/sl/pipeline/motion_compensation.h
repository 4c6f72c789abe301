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
//
// Lens distortion: a lateral motion past a fronto-parallel scene shifts the
// undistorted (pinhole) image uniformly, but the distorted image by an amount
// that varies over it, along the axis (k1 (3 x^2 + y^2)) and across it
// (2 k1 x y). Shifting the distorted frames as a whole leaves the pixels
// away from the image axes looking at points displaced across the fringes: a
// depth error ~ x y that twists every scan (sl_eval wall: -0.018 x y mm, x, y
// in 100 mm, and 0.4 mm of drift over a 50 cm pass). Given the cameras'
// models, a camera with distortion is compensated in undistorted
// coordinates: its frames are registered on their undistorted images, and
// each pixel is resampled (bilinear, in floating point) from where the model
// puts its undistorted position moved by the shift.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct MotionCompensationOptions {
  enum class Axis { kX, kY } axis = Axis::kX;  // image axis along which the scene moves
  int reference_frame = -1;    // index in the sequence; -1 = the middle frame
  int subsample = 2;           // register on images downsampled by this factor (1, 2, 4)
  bool window = true;          // Hann window against edge effects
  double max_shift_px = 200;   // the shift is searched within +-max_shift_px
  // Consistency along the sequence (needs at least 3 frames besides the
  // reference): under linear motion a frame's shift is the sequence's speed
  // (px per ns, the median of shift / (stamp - reference stamp) over its
  // frames) times its time from the reference. A frame whose shift differs
  // from that by more than max(max_deviation_px, max_deviation_fraction *
  // |predicted|) took a false correlation peak: it is registered again
  // within that band around the prediction, and moved by the prediction if
  // its correlation has no peak there. 0 turns the check off.
  // (Generous: a sequence may accelerate; sl_eval motion's 1 -> 3 mm per
  // image is off a constant speed by 38 % at its ends. False peaks lie tens
  // to hundreds of px away.)
  double max_deviation_px = 5.0;
  double max_deviation_fraction = 0.5;
};

struct MotionEstimate {
  // Per camera, per frame: position of the frame's content relative to the
  // reference frame along the axis (px, full resolution; for a camera
  // compensated in undistorted coordinates, px of its pinhole image: the
  // shift near the principal point). The reference is 0.
  std::vector<std::vector<double>> shifts_px;
  bool all_within_limit = true;
  // Frames whose own estimate disagreed with the sequence's motion and was
  // replaced (options' max_deviation_px): all cameras, per camera per frame.
  int frames_corrected = 0;
  std::vector<std::vector<bool>> corrected;
};

// Thread-compatible; holds its options, the undistortion of the cameras it
// was given and a cached window.
class MotionCompensator {
 public:
  // `cameras`: the models of the cameras by camera id (CameraImages'
  // camera_id); the frames of a camera whose model has distortion are
  // compensated in undistorted coordinates (above), the others (no model or
  // no distortion) by a shift of the whole frame. Throws
  // std::invalid_argument on bad options or a model without a size.
  explicit MotionCompensator(MotionCompensationOptions options,
                             const std::map<std::string, PinholeModel>& cameras = {});

  // Shift of `moving`'s content relative to `reference` along the axis (px).
  // Both images the same size, CV_8UC1 / CV_16UC1 / CV_32FC1. A correlation
  // whose maximum lies on the edge of the +-max_shift_px search range has no
  // peak within it: the result is then beyond max_shift_px (by the sign).
  double estimateShift(const cv::Mat& reference, const cv::Mat& moving) const;
  // The same with the peak searched within [from_px, to_px] only: NaN when
  // the correlation has no maximum inside (it rises beyond an end) or the
  // maximum inside is below 0.3 of the correlation's global maximum (a side
  // lobe).
  double estimateShiftWithin(const cv::Mat& reference, const cv::Mat& moving, double from_px,
                             double to_px) const;

  // A new image set whose frames are aligned with the reference frame (by
  // sub-pixel resampling along the axis, or through the camera's model),
  // stamped with the reference frame's time. A pixel whose source lies even
  // partly outside the frame in any frame of the camera is 0 in all of its
  // frames (the reference included), so the decoder finds no modulation there
  // and marks it invalid. Throws std::invalid_argument on an empty set, a bad
  // reference or frames whose size differs from their camera's model.
  std::shared_ptr<const ImageSet> compensate(const ImageSet& set,
                                             MotionEstimate* estimate = nullptr) const;

  const MotionCompensationOptions& options() const { return options_; }

 private:
  struct Lens;  // a camera's undistortion (motion_compensation.cpp)

  // One frame's spectrum, as the correlation takes it: subsampled (and
  // undistorted through `lens` when given), transposed for the y axis, mean
  // removed, windowed.
  cv::Mat spectrum(const cv::Mat& image, const Lens* lens) const;
  // The correlation along the axis (subsampled px, circular) of the frame
  // of spectrum `moving` against that of `reference`.
  cv::Mat correlate(const cv::Mat& reference, const cv::Mat& moving) const;
  double peakShift(const cv::Mat& correlation) const;
  double peakShiftWithin(const cv::Mat& correlation, double from_px, double to_px) const;

  MotionCompensationOptions options_;
  std::map<std::string, std::shared_ptr<const Lens>> lenses_;  // cameras with distortion
  mutable cv::Mat window_;  // cached Hann window for the last size (thread-compatible)
};

}  // namespace sl::pipeline
