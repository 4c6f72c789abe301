#include "sl/pipeline/decoder.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "fast_atan2.h"

namespace sl::pipeline {

namespace {

constexpr float kTwoPi = 2.0f * std::numbers::pi_v<float>;
constexpr float kInvTwoPi = 1.0f / kTwoPi;
constexpr float kSqrt3 = 1.7320508075688772f;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Per-direction constants of the unwrapping and validity tests.
struct DirectionParams {
  int first_frame;         // index of the direction's first high-frequency frame
  int fringes;             // N_fringe
  float wavelength;        // lambda = L / N_fringe, projector px
  float axis_length;       // L, projector px
  float min_modulation;    // B threshold in camera DN
  float saturation_level;  // 2^bit_depth - 1, or +inf when not rejecting
  float max_unwrap_error;  // periods
};

static_assert(static_cast<int>(PixelStatus::kValid) == 0, "outputRow tests status == 0");

// Scratch rows reused across the rows of one decode call.
struct RowBuffers {
  std::vector<float> phase_high, phase_low, modulation, peak, coord;
  std::vector<std::int32_t> status;
  explicit RowBuffers(int width)
      : phase_high(width), phase_low(width), modulation(width), peak(width), coord(width),
        status(width) {}
};

// Per-row kernels. They are written without branches and take __restrict
// pointers so that GCC vectorizes them at -O3 without runtime alias checks
// (SSE2 baseline; needs -fno-math-errno -fno-trapping-math, set for this file
// in CMakeLists.txt).

// Wrapped phases (eq. 2) of both sets, (3B)^2 of the high-frequency set, the
// brightest of the six values and, when `offset` is not null, A.
template <typename Pixel>
void phaseRow(int n, const Pixel* __restrict i0, const Pixel* __restrict i1,
              const Pixel* __restrict i2, const Pixel* __restrict l0, const Pixel* __restrict l1,
              const Pixel* __restrict l2, float* __restrict phase_high,
              float* __restrict phase_low, float* __restrict b2, float* __restrict peak,
              float* __restrict offset) {
  for (int x = 0; x < n; ++x) {
    const float a0 = i0[x], a1 = i1[x], a2 = i2[x];
    const float c0 = l0[x], c1 = l1[x], c2 = l2[x];
    const float sin_h = kSqrt3 * (a1 - a2);  // 3B sin(phi_h)
    const float cos_h = 2.0f * a0 - a1 - a2;  // 3B cos(phi_h)
    const float sin_l = kSqrt3 * (c1 - c2);
    const float cos_l = 2.0f * c0 - c1 - c2;
    phase_high[x] = detail::fastAtan2Positive(sin_h, cos_h);
    phase_low[x] = detail::fastAtan2Positive(sin_l, cos_l);
    b2[x] = sin_h * sin_h + cos_h * cos_h;
    peak[x] = std::max(std::max(std::max(a0, a1), std::max(a2, c0)), std::max(c1, c2));
  }
  if (offset) {
    for (int x = 0; x < n; ++x) offset[x] = (float(i0[x]) + float(i1[x]) + float(i2[x])) / 3.0f;
  }
}

// Constants of unwrapRow, precomputed from DirectionParams.
struct UnwrapConstants {
  float n_fringes, wavelength, max_coord, min_b2, max_unwrap_error, saturation_level;
};

// Temporal unwrapping (eq. 3-4), projector coordinate (eq. 5) and status.
// cycles lies in (-1, N); the fringe order k is taken modulo N because the
// code is periodic in p with period L (k = -1 and k = N are the neighbours of
// the wrap).
void unwrapRow(int n, const UnwrapConstants c, const float* __restrict phase_high,
               const float* __restrict phase_low, const float* __restrict b2,
               const float* __restrict peak, float* __restrict coord,
               std::int32_t* __restrict status) {
  for (int x = 0; x < n; ++x) {
    const float cycles = (c.n_fringes * phase_low[x] - phase_high[x]) * kInvTwoPi;
    // round(cycles) for cycles > -1.5, as a truncation (no libm call).
    const float k_raw = static_cast<float>(static_cast<std::int32_t>(cycles + 1.5f) - 1);
    const float unwrap_error = std::fabs(cycles - k_raw);
    float k = k_raw < 0.0f ? k_raw + c.n_fringes : k_raw;
    k = k >= c.n_fringes ? k - c.n_fringes : k;
    const float p = (phase_high[x] * kInvTwoPi + k) * c.wavelength;
    coord[x] = p;
    std::int32_t s = p >= -0.5f && p <= c.max_coord
                         ? static_cast<std::int32_t>(PixelStatus::kValid)
                         : static_cast<std::int32_t>(PixelStatus::kOutOfRange);
    s = unwrap_error > c.max_unwrap_error
            ? static_cast<std::int32_t>(PixelStatus::kUnwrapInconsistent)
            : s;
    s = b2[x] >= c.min_b2 ? s : static_cast<std::int32_t>(PixelStatus::kLowModulation);
    s = peak[x] >= c.saturation_level ? static_cast<std::int32_t>(PixelStatus::kSaturated) : s;
    status[x] = s;
  }
}

// Writes B, the projector coordinate (NaN unless valid) and the status of a
// row. With `combine` (second direction of kBoth) B keeps the minimum of both
// directions and an earlier invalid status wins.
void outputRow(int n, bool combine, const float* __restrict b2, const float* __restrict p,
               std::int32_t* __restrict status, float* __restrict modulation_out,
               float* __restrict coord_out, std::uint8_t* __restrict status_out) {
  if (combine) {
    for (int x = 0; x < n; ++x) {
      modulation_out[x] = std::min(modulation_out[x], std::sqrt(b2[x]) * (1.0f / 3.0f));
    }
    for (int x = 0; x < n; ++x) status[x] = status_out[x] != 0 ? status_out[x] : status[x];
  } else {
    for (int x = 0; x < n; ++x) modulation_out[x] = std::sqrt(b2[x]) * (1.0f / 3.0f);
  }
  for (int x = 0; x < n; ++x) coord_out[x] = status[x] == 0 ? p[x] : kNaN;
  for (int x = 0; x < n; ++x) status_out[x] = static_cast<std::uint8_t>(status[x]);
}

// Decodes one direction (frames first_frame .. first_frame + 5) into `coord`.
// Without `combine`, modulation/offset/status are written; with it (second
// direction of kBoth), see outputRow.
template <typename Pixel>
void decodeDirection(const std::vector<cv::Mat>& frames, const DirectionParams& d, bool combine,
                     cv::Mat& coord, cv::Mat& modulation, cv::Mat& offset, cv::Mat& status) {
  const int rows = frames[0].rows;
  const int cols = frames[0].cols;
  RowBuffers buf(cols);
  const UnwrapConstants constants{static_cast<float>(d.fringes),
                                  d.wavelength,
                                  d.axis_length - 0.5f,
                                  9.0f * d.min_modulation * d.min_modulation,  // on (3B)^2
                                  d.max_unwrap_error,
                                  d.saturation_level};
  const int f = d.first_frame;
  for (int y = 0; y < rows; ++y) {
    phaseRow<Pixel>(cols, frames[f].ptr<Pixel>(y), frames[f + 1].ptr<Pixel>(y),
                    frames[f + 2].ptr<Pixel>(y), frames[f + 3].ptr<Pixel>(y),
                    frames[f + 4].ptr<Pixel>(y), frames[f + 5].ptr<Pixel>(y),
                    buf.phase_high.data(), buf.phase_low.data(), buf.modulation.data(),
                    buf.peak.data(), combine ? nullptr : offset.ptr<float>(y));
    unwrapRow(cols, constants, buf.phase_high.data(), buf.phase_low.data(), buf.modulation.data(),
              buf.peak.data(), buf.coord.data(), buf.status.data());
    outputRow(cols, combine, buf.modulation.data(), buf.coord.data(), buf.status.data(),
              modulation.ptr<float>(y), coord.ptr<float>(y), status.ptr<std::uint8_t>(y));
  }
}

void checkFrames(const std::vector<cv::Mat>& frames, int expected_count, int bit_depth) {
  if (static_cast<int>(frames.size()) != expected_count) {
    throw std::invalid_argument("PhaseShift33Decoder: expected " + std::to_string(expected_count) +
                                " frames, got " + std::to_string(frames.size()));
  }
  const cv::Mat& first = frames.front();
  if (first.empty()) throw std::invalid_argument("PhaseShift33Decoder: frame 0 is empty");
  if (first.type() != CV_8UC1 && first.type() != CV_16UC1) {
    throw std::invalid_argument("PhaseShift33Decoder: frames must be CV_8UC1 or CV_16UC1");
  }
  for (std::size_t i = 1; i < frames.size(); ++i) {
    if (frames[i].size() != first.size()) {
      throw std::invalid_argument("PhaseShift33Decoder: frame " + std::to_string(i) +
                                  " differs in size from frame 0");
    }
    if (frames[i].type() != first.type()) {
      throw std::invalid_argument("PhaseShift33Decoder: frame " + std::to_string(i) +
                                  " differs in type from frame 0");
    }
  }
  const int max_bits = first.type() == CV_8UC1 ? 8 : 16;
  if (bit_depth < 1 || bit_depth > max_bits) {
    throw std::invalid_argument("PhaseShift33Decoder: bit_depth " + std::to_string(bit_depth) +
                                " is outside 1.." + std::to_string(max_bits) +
                                " for this image type");
  }
}

}  // namespace

PhaseShift33Decoder::PhaseShift33Decoder(PhaseShift33Pattern pattern, DecoderOptions options)
    : pattern_(std::move(pattern)), options_(options) {
  pattern_.validate();
  if (!(options_.min_modulation >= 0.0f)) {
    throw std::invalid_argument("DecoderOptions: min_modulation must be >= 0");
  }
  if (!(options_.max_unwrap_error > 0.0f && options_.max_unwrap_error <= 0.5f)) {
    throw std::invalid_argument("DecoderOptions: max_unwrap_error must be in (0, 0.5]");
  }
}

ProjectorMaps PhaseShift33Decoder::decode(const std::vector<cv::Mat>& frames,
                                          int bit_depth) const {
  checkFrames(frames, pattern_.frameCount(), bit_depth);
  const cv::Size size = frames.front().size();

  ProjectorMaps maps;
  // Encoded maps are written in full below; the other one is all NaN.
  maps.up = cv::Mat(size, CV_32FC1);
  maps.vp = cv::Mat(size, CV_32FC1);
  if (pattern_.direction == Direction::kVertical) maps.up.setTo(kNaN);
  if (pattern_.direction == Direction::kHorizontal) maps.vp.setTo(kNaN);
  maps.modulation = cv::Mat(size, CV_32FC1);
  maps.offset = cv::Mat(size, CV_32FC1);
  maps.status = cv::Mat(size, CV_8UC1);

  const float dn_scale = std::ldexp(1.0f, bit_depth - 8);
  const float saturation = options_.reject_saturated
                               ? static_cast<float>((1 << bit_depth) - 1)
                               : std::numeric_limits<float>::infinity();
  auto params = [&](int first_frame, int axis_length) {
    return DirectionParams{first_frame,
                           pattern_.fringes,
                           static_cast<float>(pattern_.wavelength(axis_length)),
                           static_cast<float>(axis_length),
                           options_.min_modulation * dn_scale,
                           saturation,
                           options_.max_unwrap_error};
  };
  const DirectionParams columns = params(0, pattern_.projector_width);
  const DirectionParams rows_first = params(0, pattern_.projector_height);
  const DirectionParams rows_second = params(6, pattern_.projector_height);

  auto run = [&](const DirectionParams& d, bool combine, cv::Mat& coord) {
    if (frames.front().type() == CV_8UC1) {
      decodeDirection<std::uint8_t>(frames, d, combine, coord, maps.modulation, maps.offset,
                                    maps.status);
    } else {
      decodeDirection<std::uint16_t>(frames, d, combine, coord, maps.modulation, maps.offset,
                                     maps.status);
    }
  };

  switch (pattern_.direction) {
    case Direction::kHorizontal:
      run(columns, false, maps.up);
      break;
    case Direction::kVertical:
      run(rows_first, false, maps.vp);
      break;
    case Direction::kBoth: {
      run(columns, false, maps.up);
      run(rows_second, true, maps.vp);
      // A pixel is valid only when both directions are: clear u_p where the
      // vertical set failed.
      for (int y = 0; y < size.height; ++y) {
        const auto* s = maps.status.ptr<std::uint8_t>(y);
        float* up = maps.up.ptr<float>(y);
        for (int x = 0; x < size.width; ++x) {
          if (s[x] != static_cast<std::uint8_t>(PixelStatus::kValid)) up[x] = kNaN;
        }
      }
      break;
    }
  }
  return maps;
}

}  // namespace sl::pipeline
