// Decodes 3+3 phase-shift images into projector coordinate maps (eq. 2-5).
#pragma once

#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/pattern.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct DecoderOptions {
  float min_modulation = 8.0f;    // B in DN (8-bit scale) below which a pixel is invalid
  bool reject_saturated = true;   // any frame at (2^bit_depth - 1) invalidates the pixel
  // |N*phi_l - phi_h - 2*pi*k| / (2*pi) above this marks an unwrapping
  // inconsistency (the cue and the fine phase disagree by this many periods).
  float max_unwrap_error = 0.35f;
};

// Thread-compatible; holds only its configuration.
//
// Output contract of decode():
// - up / vp: projector column / row in projector px, with the convention of
//   patternIntensity() (a camera pixel that sees the centre of projector
//   column c decodes to c). The 3+3 code is periodic along the axis (period
//   L), so decoded values lie in [0, L); values above L - 0.5 cannot be told
//   from the half pixel left of column 0 and are reported kOutOfRange.
//   Maps of a direction that the pattern does not encode are all NaN.
// - modulation: B of the high-frequency set (for kBoth the smaller of the
//   two directions), offset: A of the first high-frequency set, camera DN.
// - status: the first failing test in the order saturated, low modulation,
//   unwrap inconsistency, out of range. For kBoth a pixel is valid only when
//   both directions are; otherwise up and vp are both NaN.
// DecoderOptions are checked by the constructor (std::invalid_argument).
class PhaseShift33Decoder {
 public:
  PhaseShift33Decoder(PhaseShift33Pattern pattern, DecoderOptions options);

  // frames: pattern.frameCount() images of one camera in projection order,
  // CV_8UC1 or CV_16UC1. Throws std::invalid_argument on a wrong count,
  // type or size (a programming error upstream, not a per-frame fault).
  ProjectorMaps decode(const std::vector<cv::Mat>& frames, int bit_depth) const;

  const PhaseShift33Pattern& pattern() const { return pattern_; }

 private:
  PhaseShift33Pattern pattern_;
  DecoderOptions options_;
};

}  // namespace sl::pipeline
