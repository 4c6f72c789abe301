// Motion compensation for linear motion (paper section 2.4.2, eq. 9-11).
//
// When the sensor moves along one image axis, perpendicular to the fringes,
// the projector coordinate seen by a scene point does not change, only its
// position in the image. Every image of a sequence is registered to a
// reference image of the same sequence by phase correlation (not by
// interpolating between frames, so non-uniform motion is handled), and
// resampled so that it aligns with the reference.
//
// The registration is one-dimensional: the frames are averaged into lines
// along the motion axis (8 px across it), each line is transformed along the
// axis, and the lines' cross-power spectra (eq. 10) are summed (by Parseval
// the 2-D cross-power spectrum summed over the frequencies across the axis:
// its inverse transform is the correlation on the line of zero shift across
// the axis) and whitened
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

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/row_workers.h"
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

// What the sensor's own motion (e.g. the robot's velocity times each frame's
// time from the reference, through the camera's focal length at the working
// distance) says each frame's shift should be: a prior on the registration.
// For a camera listed here each frame's shift is searched only within
// +-tolerance_px of its expected shift (px along the axis, full resolution,
// as MotionEstimate::shifts_px: relative to the reference frame, whose own
// entry is subtracted; for a camera compensated in undistorted coordinates,
// pinhole px), so a stronger false
// peak elsewhere (a repetitive scene, a second copy of the texture) cannot
// win; a frame whose correlation has no peak within that band (as
// estimateShiftWithin: no maximum inside, or one below 0.3 of the global
// maximum) is moved by its expected shift. Cameras not listed are registered
// without a prior. The consistency check along the sequence (options) still
// applies afterwards.
struct MotionPrior {
  std::map<std::string, std::vector<double>> expected_shifts_px;  // by camera id, per frame
  double tolerance_px = 8.0;
};

// The expected shifts of the frames stamped `stamps_ns` (ns) of a camera
// moving at `velocity_mm_s` along its image axis (the optical frame's x for
// Axis::kX, y for kY) past a scene at `depth_mm`, seen with focal length
// `focal_px` along that axis: -velocity (t_i - t_0) focal / depth px (the
// content moves against the camera), for MotionPrior.
std::vector<double> expectedShiftsPx(double velocity_mm_s, double focal_px, double depth_mm,
                                     const std::vector<std::int64_t>& stamps_ns);

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
  // Frames that a MotionPrior moved by their expected shift because their
  // correlation had no peak near it (all cameras).
  int frames_at_prior = 0;
};

// Thread-compatible (its const methods may run concurrently); holds its
// options and the undistortion of the cameras it was given.
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
  // The frames are registered one per thread and resampled in blocks of
  // rows on `workers` when given (the caller's pool, e.g. the daemon's
  // processing threads), else on OpenCV's threads.
  // `prior` (optional): the expected shifts (MotionPrior); throws
  // std::invalid_argument when a listed camera's list does not have one
  // entry per frame or the tolerance is not > 0.
  std::shared_ptr<const ImageSet> compensate(const ImageSet& set, MotionEstimate* estimate = nullptr,
                                             RowWorkers* workers = nullptr,
                                             const MotionPrior* prior = nullptr) const;

  const MotionCompensationOptions& options() const { return options_; }

 private:
  struct Lens;  // a camera's undistortion (motion_compensation.cpp)

  // Where a frame is registered: averaged over `along` px along the axis
  // (the subsample factor) and `across` px across it, into `lines` lines
  // across the axis of `samples` samples along it.
  struct Registration {
    bool along_x = true;
    int along = 1, across = 1;
    int lines = 0, samples = 0;
  };
  // Throws std::invalid_argument for images too small to register.
  Registration registration(cv::Size size) const;

  // One frame's spectrum, as the correlation takes it: averaged (and
  // undistorted through `lens` when given) into lines along the axis, mean
  // removed, windowed, each line transformed (CCS packed rows).
  cv::Mat spectrum(const cv::Mat& image, const Lens* lens) const;
  // The correlation along the axis (subsampled px, circular) of the frame
  // of spectrum `moving` against that of `reference`.
  cv::Mat correlate(const cv::Mat& reference, const cv::Mat& moving) const;
  double peakShift(const cv::Mat& correlation) const;
  double peakShiftWithin(const cv::Mat& correlation, double from_px, double to_px) const;
  // `frame` moved by -shift along the axis (through `lens` when given);
  // pixels whose source lies even partly outside it are 0 and set in
  // `lacking` (CV_8UC1).
  cv::Mat resample(const cv::Mat& frame, double shift, const Lens* lens, cv::Mat& lacking,
                   RowWorkers* workers) const;

  MotionCompensationOptions options_;
  std::map<std::string, std::shared_ptr<const Lens>> lenses_;  // cameras with distortion
};

}  // namespace sl::pipeline
