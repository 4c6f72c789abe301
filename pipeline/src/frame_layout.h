// Canonical frame layout of a PatternSpec (private to the pipeline): what
// each frame of a sequence shows, before the optional frame_order permutation.
#pragma once

#include <vector>

#include "sl/pipeline/pattern_spec.h"

namespace sl::pipeline::detail {

struct FrameInfo {
  enum class Kind { kSinusoid, kFlat, kWhite, kBlack, kGrayBit };
  Kind kind = Kind::kFlat;
  bool columns = true;     // encodes u_p (true) or v_p (false)
  // kSinusoid: I = offset + amplitude * cos(2*pi*frequency*(p - origin)/L - delta).
  double frequency = 0;    // periods across the axis
  double origin = 0;       // px
  double delta = 0;        // rad
  // kSinusoid of kModulatedPhaseShift: times 0.5 + 0.5 cos(2*pi*q/carrier_pitch
  // - carrier_shift), q the other axis' coordinate; carrier_pitch 0 = none.
  double carrier_pitch = 0;    // px
  double carrier_shift = 0;    // rad
  // kGrayBit: bit `bit` (0 = MSB) of the `code_bits`-bit reflected Gray code
  // of the stripe index floor((p + 0.5) / stripe); inverted swaps 0 and 1.
  int bit = 0;
  int code_bits = 0;
  double stripe = 1;       // px
  bool inverted = false;
};

// One entry per frame of the full sequence, canonical order (horizontal
// block then vertical block for kBoth).
std::vector<FrameInfo> canonicalFrames(const PatternSpec& spec);

// Relative intensity in [0, 1] of a frame at projector coordinate (u, v).
double frameIntensity(const PatternSpec& spec, const FrameInfo& f, double u, double v);

}  // namespace sl::pipeline::detail
