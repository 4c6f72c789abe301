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
