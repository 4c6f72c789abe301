// Legacy 3+3 decoder API, kept for existing users: a thin wrapper over the
// phase-shift codec (codec.h) of toSpec(pattern). New code uses
// makeCodec() / Decoder with a PatternSpec.
#pragma once

#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/pattern.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// Thread-compatible; immutable after construction. decode() follows the
// Codec output contract (codec.h). DecoderOptions and the pattern are
// checked by the constructor (std::invalid_argument).
class PhaseShift33Decoder {
 public:
  PhaseShift33Decoder(PhaseShift33Pattern pattern, DecoderOptions options);

  // frames: pattern.frameCount() images of one camera in projection order,
  // CV_8UC1 or CV_16UC1. Throws std::invalid_argument on a wrong count,
  // type or size (a programming error upstream, not a per-frame fault).
  ProjectorMaps decode(const std::vector<cv::Mat>& frames, int bit_depth) const {
    return decoder_.decode(frames, bit_depth);
  }

  const PhaseShift33Pattern& pattern() const { return pattern_; }

 private:
  PhaseShift33Pattern pattern_;
  Decoder decoder_;
};

}  // namespace sl::pipeline
