// Decoders: the per-pattern Decoder over a shared Codec (codec.h) that the
// daemon and the tools keep, and PhaseShift33Decoder, the 3+3 convenience
// wrapper of toSpec(pattern) that the analytic tests and benchmarks use.
#pragma once

#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/pattern.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// A decoder by value: shares one immutable codec. Thread-compatible, cheap to
// copy; what the daemon keeps per pattern.
class Decoder {
 public:
  Decoder(const PatternSpec& spec, const DecoderOptions& options);
  ProjectorMaps decode(const std::vector<cv::Mat>& frames, int bit_depth) const {
    return codec_->decode(frames, bit_depth);
  }
  const Codec& codec() const { return *codec_; }
  const PatternSpec& spec() const { return codec_->spec(); }

 private:
  std::shared_ptr<const Codec> codec_;
};

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
