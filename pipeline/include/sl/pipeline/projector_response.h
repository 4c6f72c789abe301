// A projector's intensity response and its compensation in decoding.
//
// A projector in video mode shows relative intensity L through a response
// R(L) (a gamma curve, R = L^gamma, about 2.2 for sRGB) instead of linearly.
// The phase of every sinusoid set then has a periodic error that depends
// only on R (not on a pixel's gain or ambient light): at gamma 2.2 enough to
// break temporal unwrapping from a unit-frequency cue. Given R
// (DecoderOptions::projector_response), the phase-shift codec replaces each
// set's measured phase by the true one through a table built from R; R comes
// from a ramp of grey levels (estimateProjectorResponse) or from phase-shift
// captures themselves (estimateProjectorGamma).
#pragma once

#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/pattern_spec.h"

namespace sl::pipeline {

// R(L) = L^gamma sampled at L = k / (samples - 1). Throws
// std::invalid_argument for gamma <= 0 or samples < 2.
std::vector<float> gammaResponse(double gamma, int samples = 256);

// Checks a response for DecoderOptions: >= 2 finite samples, strictly
// increasing. Throws std::invalid_argument naming the problem.
void validateProjectorResponse(const std::vector<float>& response);

// The response from camera images of flat frames at relative levels
// `levels` (ascending, in [0, 1], the first and last at least 0.5 apart),
// one frame each (CV_8UC1 or CV_16UC1, one size): per pixel the frames
// normalised to the first and last level ((I_k - I_first) / (I_last -
// I_first), pixels with a contrast of at least `min_contrast_dn` (8-bit
// scale) and none saturated), the median over the pixels per level, then
// resampled to `samples` uniform levels (linear between the measured ones,
// R(0) and R(1) extrapolated from the first and last). Throws
// std::invalid_argument on bad input or too few usable pixels.
std::vector<float> estimateProjectorResponse(const std::vector<cv::Mat>& frames,
                                             const std::vector<double>& levels, int bit_depth,
                                             double min_contrast_dn = 20.0, int samples = 256);

// The gamma of R = L^gamma that makes the sets of one phase-shift capture
// (family kPhaseShift, hierarchical unwrapping, >= 2 frequencies) agree
// best: the mean squared unwrapping residual (coarse phase scaled to the
// finer one minus the finer one, in periods, after the nearest whole period)
// over the pixels with enough modulation, minimised over gamma in [0.3, 4]
// (grid, then golden section). The true phases of the sets are tied by
// their frequencies, a gamma error is not: a wall or any surface works.
// Throws std::invalid_argument for other patterns or too few usable pixels.
struct GammaEstimate {
  double gamma = 1.0;
  double rms_residual_periods = 0;         // at the estimate
  double rms_residual_linear_periods = 0;  // with gamma 1 (no compensation)
  long pixels = 0;                         // used
};
GammaEstimate estimateProjectorGamma(const PatternSpec& spec, const std::vector<cv::Mat>& frames,
                                     int bit_depth, float min_modulation_dn = 20.0f);

}  // namespace sl::pipeline
