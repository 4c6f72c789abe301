// Row kernels of the phase-shift codec for two 3-step sets unwrapped
// hierarchically (the 3+3 patterns), exposed so that test_decoder can run
// the AVX-512 kernel and the portable one on the same rows (private).
#pragma once

#include <cstdint>

namespace sl::pipeline::detail {

// Per-row constants of the two-set unwrapping (see twoSetPixel() in
// codec_phase_shift.cpp).
struct TwoSetConstants {
  float ratio;       // fine / coarse frequency
  float to_px;       // absolute fine phase -> projector px
  float period;      // code period, projector px
  float inv_period;  // 1 / period
  float max_coord;   // L - 0.5
  float min_b2;      // (min modulation)^2, camera DN^2
  float max_err;     // unwrapping error bound, cycles
  float saturation;  // peak >= saturation: saturated
};

// The sin / cos weights of one 3-step set's frames and its B^2 scale.
struct ThreeStepWeights {
  float ws[3];
  float wc[3];
  float scale2;
};

struct TwoThreeStepParams {
  ThreeStepWeights fine, coarse;
  bool offset_from_fine;  // offset A = mean of the fine (else the coarse) frames
  TwoSetConstants k;
};

struct TwoThreeStepOutput {
  float* coord;
  float* modulation;
  float* offset;
  std::uint8_t* status;
  float* residual;
  float* scratch;  // `width` floats (the portable kernel's status codes)
};

// rows: the fine set's three frame rows, then the coarse set's.
void twoThreeStepRow(const TwoThreeStepParams& p, const std::uint8_t* const* rows, int width,
                     const TwoThreeStepOutput& out);
void twoThreeStepRow(const TwoThreeStepParams& p, const std::uint16_t* const* rows, int width,
                     const TwoThreeStepOutput& out);

// The same for 8-bit rows with AVX-512 intrinsics, bit for bit the same
// results; only callable when twoThreeStepAvx512Supported().
bool twoThreeStepAvx512Supported();
void twoThreeStepRowAvx512(const TwoThreeStepParams& p, const std::uint8_t* const* rows, int width,
                           const TwoThreeStepOutput& out);

}  // namespace sl::pipeline::detail
