// Decode health of one scan: does what was decoded look like frames of the
// pattern the decoder was told about? A wrong description (frequencies in the
// wrong order, another period, another steps x frequencies split) still
// yields "valid" pixels, but their consistency residuals (ProjectorMaps::
// residual) spread uniformly over [0, 0.5] periods instead of gathering near
// 0, and many pixels fail unwrapping. Measured from the maps the codec wrote
// (status and residual of every pixel) and from the frames (modulation per
// frequency, on a sparse grid). Thresholds and their measurements:
// docs/decode-health.md.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// Where a decode stops being plausible. Fractions are of the modulated
// pixels (valid, unwrap inconsistent or out of range: above the modulation
// threshold and not saturated).
struct DecodeHealthLimits {
  // Fewer modulated pixels than this: too little to judge (not implausible).
  std::int64_t min_modulated_pixels = 2000;
  // Implausible above these (codes with a consistency test only).
  double max_inconsistent_fraction = 0.20;
  double max_median_residual = 0.17;  // periods (micro phase shift: RMS cosine)
  // Implausible above this (every code): the coordinates run past the
  // projector, which a right description only gives through noise at the
  // last pixel (another period or pitch than the one projected, or another
  // projector size).
  double max_out_of_range_fraction = 0.02;
  // A warning above this fraction of all pixels.
  double max_saturated_fraction = 0.05;
  // Epipolar consistency (addEpipolarCheck, both projector axes decoded and
  // a calibration): implausible when the median distance of the decoded
  // projector coordinate (up, vp) to the epipolar line of its camera pixel
  // exceeds this (projector px).
  double max_epipolar_median_px = 5.0;
  // Fewer valid pixels with both coordinates than this: not judged.
  std::int64_t min_epipolar_pixels = 2000;
};

// Median modulation B (8-bit DN, i.e. camera DN / 2^(bit_depth - 8)) of one
// sinusoid set of the pattern over the modulated pixels of a sparse grid.
struct FrequencyModulation {
  bool columns = true;     // the set encodes u_p (else v_p)
  double frequency = 0;    // periods across the axis
  double median_b_dn = 0;  // 8-bit DN
};

struct DecodeHealth {
  std::int64_t pixels = 0;
  std::int64_t valid = 0, low_modulation = 0, saturated = 0, inconsistent = 0, out_of_range = 0;
  std::int64_t modulated() const { return valid + inconsistent + out_of_range; }
  // modulated / pixels.
  double modulatedFraction() const;
  // (valid + out_of_range) / modulated: pixels whose code agreed with itself.
  double consistentFraction() const;
  double inconsistentFraction() const;   // inconsistent / modulated
  double outOfRangeFraction() const;     // out_of_range / modulated
  double saturatedFraction() const;      // saturated / pixels

  // The code has a consistency test (>= 2 frequencies, micro phase shift,
  // Gray + phase shift with the complementary bit); without one the residual
  // fields are 0 and a wrong description cannot be seen from one scan.
  bool has_residual = false;
  // Distribution of the residual over the modulated pixels: quantiles and
  // the fraction in each bin [0.05 i, 0.05 (i + 1)) periods, the last bin
  // everything from 0.5 up. Uniform residuals (a wrong description) give a
  // median near 0.25 and about 0.1 per bin.
  double residual_median = 0, residual_p90 = 0;
  std::array<double, 11> residual_histogram{};
  double max_unwrap_error = 0;  // the decoder's bound, for the reader

  std::vector<FrequencyModulation> modulation;

  // Epipolar consistency (addEpipolarCheck): distance (projector px) of the
  // decoded (up, vp) of each valid pixel to the epipolar line the
  // calibration gives its camera pixel. A right description leaves the
  // calibration's error; another pitch or period scales a coordinate away
  // from the line. Only with both axes decoded and a calibration.
  bool has_epipolar = false;
  std::int64_t epipolar_pixels = 0;
  double epipolar_median_px = 0, epipolar_p90_px = 0;

  // Judgement against DecodeHealthLimits: `implausible` with one sentence per
  // failed limit in `problems`; `warnings` for what deserves a look.
  bool implausible = false;
  std::vector<std::string> problems;
  std::vector<std::string> warnings;
};

// Whether a code of `spec` has a consistency test (>= 2 frequencies, micro
// phase shift, Gray + phase shift with the complementary bit): without one
// a wrong description cannot be seen from one scan.
bool hasConsistencyTest(const PatternSpec& spec);

// The counts behind a DecodeHealth, gathered band by band while the maps are
// still in cache (ScanProcessor::process with a tally: the daemon never
// writes its maps out). The status of every pixel is counted; the residual
// of the modulated pixels on a grid of every kResidualStep-th pixel of every
// kResidualStep-th image row (1/16 of them: a histogram increment per pixel
// would cost a third of a 3+3 scan), binned finely enough that quantiles
// from the bins are within half a bin (0.0025 periods) of the grid's exact
// ones.
struct DecodeTally {
  static constexpr int kBins = 100;                  // of kBinWidth, then one bin for >= 0.5
  static constexpr double kBinWidth = 0.005;         // periods
  static constexpr int kResidualStep = 4;            // grid of the residual histogram (px)
  std::array<std::int64_t, 5> status{};              // per PixelStatus (>= 4 counted as 4)
  std::array<std::int64_t, kBins + 1> residual{};    // modulated pixels of the grid only

  // Adds rows [row_begin, row_end) of `maps`' status and residual (its
  // residual only when `with_residual`); `image_row` is the image row of
  // maps row `row_begin` (a band's rows are numbered from 0), which places
  // the residual grid.
  void addRows(const ProjectorMaps& maps, int row_begin, int row_end, bool with_residual, int image_row);
  void add(const DecodeTally& other);
};

// The health of a scan from its tally alone (no modulation per frequency:
// that needs the frames): counts, residual quantiles (interpolated in the
// bins) and histogram, and the judgement of measureDecodeHealth().
DecodeHealth judgeDecodeTally(const PatternSpec& spec, const DecoderOptions& options,
                              const DecodeTally& tally, const DecodeHealthLimits& limits = {});

// Measures the health of `maps` decoded by a codec of `spec` with `options`
// (the options the codec used: Codec::options()) from `frames` (the frames
// decoded, projection order) of `bit_depth` significant bits. Throws
// std::invalid_argument when the maps lack status or residual or differ in
// size from the frames.
DecodeHealth measureDecodeHealth(const PatternSpec& spec, const DecoderOptions& options,
                                 const ProjectorMaps& maps, const std::vector<cv::Mat>& frames,
                                 int bit_depth, const DecodeHealthLimits& limits = {});

// Adds the epipolar consistency of `maps` (both axes decoded: up and vp
// finite at valid pixels) to `health` and judges it against
// limits.max_epipolar_median_px (a problem, implausible, above it). Camera
// pixels are undistorted with calibration.camera's model (give a
// distortion-free camera when the maps are of undistorted images); the
// projector's coordinates with calibration.projector's when
// `undistort_projector` (as the triangulator does with distortion
// iterations), else taken as pinhole pixels. Maps of one axis leave
// `health` as it is (has_epipolar false).
void addEpipolarCheck(DecodeHealth& health, const ProjectorMaps& maps,
                      const CameraProjectorCalibration& calibration, bool undistort_projector,
                      const DecodeHealthLimits& limits = {});

// Multi-line text (each line starting with `prefix`): counts, fractions,
// residual quantiles and histogram, modulation per frequency, problems and
// warnings.
std::string describeDecodeHealth(const DecodeHealth& health, const std::string& prefix);

}  // namespace sl::pipeline
