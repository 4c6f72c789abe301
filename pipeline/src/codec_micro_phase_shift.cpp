// Micro phase shifting (Gupta and Nayar, "Micro Phase Shifting", CVPR 2012):
// F >= 2 high frequencies in a narrow band, so that the projector's blur and
// interreflections treat them alike; F + 2 frames per direction: the first
// frequency at three shifts, every other one at the first shift only.
//
// Per pixel: the 3-step set gives the offset O, amplitude A and wrapped phase
// phi_0 of the first frequency; each further frame gives c_j = (I_j - O) / A
// = cos(2 pi f_j p / L - delta_j) at the same amplitude (the band is narrow).
// The coordinate is the candidate p_k = (phi_0 / 2 pi + k) L / f_0 whose
// predicted cosines match the c_j best (least squares over j); the cosines of
// consecutive candidates follow by rotation (angle step 2 pi f_j / f_0), so a
// pixel costs (F - 1) ceil(f_0) complex multiplications. The RMS cosine
// residual of the best candidate above max_unwrap_error marks the pixel
// kUnwrapInconsistent.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "codec_families.h"
#include "fast_atan2.h"
#include "frame_layout.h"

namespace sl::pipeline::detail {

namespace {

constexpr float kTwoPi = 2.0f * std::numbers::pi_v<float>;

class MicroPhaseShiftCodec final : public RowTemplateCodec<MicroPhaseShiftCodec> {
 public:
  MicroPhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options)
      : RowTemplateCodec(spec, options) {
    const auto frames = canonicalFrames(spec);
    for (int n = 0; n < 3; ++n) {
      ws_[n] = static_cast<float>(std::sin(frames[n].delta));
      wc_[n] = static_cast<float>(std::cos(frames[n].delta));
    }
    f0_ = spec.frequencies[0];
    for (std::size_t j = 1; j < spec.frequencies.size(); ++j) {
      delta_.push_back(static_cast<float>(frames[2 + j].delta));
      const double step = 2.0 * std::numbers::pi * spec.frequencies[j] / f0_;
      ratio_.push_back(static_cast<float>(spec.frequencies[j] / f0_));
      step_cos_.push_back(static_cast<float>(std::cos(step)));
      step_sin_.push_back(static_cast<float>(std::sin(step)));
    }
    candidates_ = static_cast<int>(std::ceil(f0_ - 1e-9));
    // The single frames of the other frequencies would need the pixel's gain
    // and ambient to be corrected: not done, so refused rather than ignored.
    if (!options.projector_response.empty())
      throw std::invalid_argument("pattern '" + spec.name +
                                  "': projector_response compensation is not implemented for "
                                  "micro_phase_shift");
  }

  int scratchRows() const override { return 0; }

 private:
  friend class RowTemplateCodec<MicroPhaseShiftCodec>;

  template <typename Pixel>
  void row(const RowContext& c, const Pixel* const* frames, int width, const RowOutput& out) const {
    const int others = static_cast<int>(ratio_.size());
    const int count = others + 3;
    const float axis = c.axis_length;
    const float wavelength = static_cast<float>(axis / f0_);
    const float min_b = options().min_modulation * c.dn_scale;
    const float max_err = options().max_unwrap_error;
    const float max_coord = axis - 0.5f;
    std::vector<float> cosines(others);
    for (int x = 0; x < width; ++x) {
      float peak = 0;
      for (int i = 0; i < count; ++i) peak = std::max(peak, static_cast<float>(frames[i][x]));
      const float i0 = frames[0][x], i1 = frames[1][x], i2 = frames[2][x];
      const float s = ws_[0] * i0 + ws_[1] * i1 + ws_[2] * i2;
      const float k = wc_[0] * i0 + wc_[1] * i1 + wc_[2] * i2;
      const float o = (i0 + i1 + i2) * (1.0f / 3.0f);
      const float a = (2.0f / 3.0f) * std::sqrt(s * s + k * k);
      const float phi = fastAtan2Positive(s, k);
      out.offset[x] = o;
      out.modulation[x] = a;
      const float inv_a = a > 0.0f ? 1.0f / a : 0.0f;
      for (int j = 0; j < others; ++j) cosines[j] = (static_cast<float>(frames[3 + j][x]) - o) * inv_a;
      // Candidate 0: p = phi / (2 pi) * wavelength.
      const float base = phi * (1.0f / kTwoPi) * wavelength;
      float best = 1e30f;
      int best_k = 0;
      // Rotating (cos, sin) of 2 pi f_j p_k / L - delta_0 per frequency.
      float cr[16], sr[16];
      for (int j = 0; j < others; ++j) {
        const float angle = kTwoPi * ratio_[j] * (phi * (1.0f / kTwoPi)) - delta_[j];
        cr[j] = std::cos(angle);
        sr[j] = std::sin(angle);
      }
      for (int cand = 0; cand < candidates_; ++cand) {
        float cost = 0;
        for (int j = 0; j < others; ++j) {
          const float d = cosines[j] - cr[j];
          cost += d * d;
          const float nc = cr[j] * step_cos_[j] - sr[j] * step_sin_[j];
          sr[j] = sr[j] * step_cos_[j] + cr[j] * step_sin_[j];
          cr[j] = nc;
        }
        if (cost < best) {
          best = cost;
          best_k = cand;
        }
      }
      const float p = base + static_cast<float>(best_k) * wavelength;
      out.coord[x] = p;
      std::uint8_t st = p >= -0.5f && p <= max_coord ? 0 : 4;
      const float residual = std::sqrt(best / static_cast<float>(others));
      out.residual[x] = residual;
      st = residual > max_err ? 3 : st;
      st = a >= min_b ? st : 1;
      st = peak >= c.saturation ? 2 : st;
      out.status[x] = st;
    }
  }

  float ws_[3]{}, wc_[3]{};
  double f0_ = 1;
  std::vector<float> delta_, ratio_, step_cos_, step_sin_;
  int candidates_ = 1;
};

}  // namespace

std::unique_ptr<Codec> makeMicroPhaseShiftCodec(const PatternSpec& spec,
                                                const DecoderOptions& options) {
  return std::make_unique<MicroPhaseShiftCodec>(spec, options);
}

}  // namespace sl::pipeline::detail
