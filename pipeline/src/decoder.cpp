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

// Scratch rows reused across the rows of one decode call.
struct RowBuffers {
  std::vector<float> phase_high, phase_low, saturated;
  explicit RowBuffers(int width) : phase_high(width), phase_low(width), saturated(width) {}
};

// Decodes one direction (frames first_frame .. first_frame + 5) into `coord`.
// When `combine` is false, modulation/offset/status are written; when true
// (second direction of kBoth), modulation keeps the minimum of both
// directions and an earlier invalid status is kept.
template <typename Pixel>
void decodeDirection(const std::vector<cv::Mat>& frames, const DirectionParams& d, bool combine,
                     cv::Mat& coord, cv::Mat& modulation, cv::Mat& offset, cv::Mat& status) {
  const int rows = frames[0].rows;
  const int cols = frames[0].cols;
  RowBuffers buf(cols);
  const float n_fringes = static_cast<float>(d.fringes);
  const float max_coord = d.axis_length - 0.5f;

  for (int y = 0; y < rows; ++y) {
    const Pixel* i0 = frames[d.first_frame + 0].ptr<Pixel>(y);
    const Pixel* i1 = frames[d.first_frame + 1].ptr<Pixel>(y);
    const Pixel* i2 = frames[d.first_frame + 2].ptr<Pixel>(y);
    const Pixel* l0 = frames[d.first_frame + 3].ptr<Pixel>(y);
    const Pixel* l1 = frames[d.first_frame + 4].ptr<Pixel>(y);
    const Pixel* l2 = frames[d.first_frame + 5].ptr<Pixel>(y);
    float* coord_row = coord.ptr<float>(y);
    float* mod_row = modulation.ptr<float>(y);
    float* off_row = offset.ptr<float>(y);
    auto* status_row = status.ptr<std::uint8_t>(y);
    float* ph = buf.phase_high.data();
    float* pl = buf.phase_low.data();
    float* sat = buf.saturated.data();

    // Pass 1, branch-free so it vectorizes: wrapped phases (eq. 2), B and A
    // of the high-frequency set, saturation flag.
    for (int x = 0; x < cols; ++x) {
      const float a0 = i0[x], a1 = i1[x], a2 = i2[x];
      const float b0 = l0[x], b1 = l1[x], b2 = l2[x];
      const float sin_h = kSqrt3 * (a1 - a2);  // 3B sin(phi_h)
      const float cos_h = 2.0f * a0 - a1 - a2;  // 3B cos(phi_h)
      const float sin_l = kSqrt3 * (b1 - b2);
      const float cos_l = 2.0f * b0 - b1 - b2;
      ph[x] = detail::fastAtan2Positive(sin_h, cos_h);
      pl[x] = detail::fastAtan2Positive(sin_l, cos_l);
      const float b = std::sqrt(sin_h * sin_h + cos_h * cos_h) * (1.0f / 3.0f);
      const float peak = std::max(std::max(std::max(a0, a1), std::max(a2, b0)), std::max(b1, b2));
      sat[x] = peak >= d.saturation_level ? 1.0f : 0.0f;
      if (combine) {
        mod_row[x] = std::min(mod_row[x], b);
      } else {
        mod_row[x] = b;
        off_row[x] = (a0 + a1 + a2) * (1.0f / 3.0f);
      }
    }

    // Pass 2: temporal unwrapping (eq. 3-4), projector coordinate (eq. 5),
    // validity. The fringe order k is taken modulo N: the code is periodic in
    // p with period L, so k = -1 and k = N are the neighbours of the wrap.
    for (int x = 0; x < cols; ++x) {
      const float cycles = (n_fringes * pl[x] - ph[x]) * kInvTwoPi;
      const float k_raw = std::nearbyint(cycles);
      const float unwrap_error = std::fabs(cycles - k_raw);
      float k = k_raw;
      if (k < 0.0f) k += n_fringes;
      if (k >= n_fringes) k -= n_fringes;
      const float p = (ph[x] * kInvTwoPi + k) * d.wavelength;

      PixelStatus s = PixelStatus::kValid;
      if (sat[x] != 0.0f) {
        s = PixelStatus::kSaturated;
      } else if (!(mod_row[x] >= d.min_modulation)) {
        s = PixelStatus::kLowModulation;
      } else if (unwrap_error > d.max_unwrap_error) {
        s = PixelStatus::kUnwrapInconsistent;
      } else if (!(p >= -0.5f && p <= max_coord)) {
        s = PixelStatus::kOutOfRange;
      }
      if (combine && status_row[x] != static_cast<std::uint8_t>(PixelStatus::kValid)) {
        s = static_cast<PixelStatus>(status_row[x]);
      }
      status_row[x] = static_cast<std::uint8_t>(s);
      coord_row[x] = s == PixelStatus::kValid ? p : kNaN;
    }
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
  maps.up = cv::Mat(size, CV_32FC1, cv::Scalar(kNaN));
  maps.vp = cv::Mat(size, CV_32FC1, cv::Scalar(kNaN));
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
