// Gray code, and Gray code + phase shift (optionally complementary).
//
// Bits are thresholded against the bit's inverse frame when projected, else
// against the mean of the white and black reference frames, else (Gray +
// phase shift without either) against the mean of the phase-shift frames. The binary value
// of the reflected Gray code accumulates MSB first (b_i = b_{i-1} xor g_i).
//
// Gray + phase shift: the n-bit code gives the fringe order k1 of a sinusoid
// with one period per stripe (phase 0 at the stripe boundary). With the
// complementary bit the (n+1)-bit value h gives k1 = h >> 1 and
// k2 = (h + 1) >> 1, whose transitions lie half a period apart; the order is
// taken from the one whose transition is far from the pixel's phase:
// k2 for phi < pi/2, k2 - 1 for phi > 3pi/2, k1 otherwise.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

#include "codec_families.h"
#include "fast_atan2.h"
#include "frame_layout.h"
#include "phase_response.h"

namespace sl::pipeline::detail {

namespace {

constexpr float kTwoPi = 2.0f * std::numbers::pi_v<float>;
constexpr float kInvTwoPi = 1.0f / kTwoPi;
constexpr float kPi = std::numbers::pi_v<float>;

class GrayCodec final : public RowTemplateCodec<GrayCodec> {
 public:
  GrayCodec(const PatternSpec& spec, const DecoderOptions& options)
      : RowTemplateCodec(spec, options) {
    const auto all = canonicalFrames(spec);
    const int per_direction = spec.framesPerDirection();
    for (int i = 0; i < per_direction; ++i) {
      const FrameInfo& f = all[i];
      switch (f.kind) {
        case FrameInfo::Kind::kWhite: white_ = i; break;
        case FrameInfo::Kind::kBlack: black_ = i; break;
        case FrameInfo::Kind::kGrayBit:
          if (f.inverted) {
            inverse_.push_back(i);
          } else {
            bits_.push_back(i);
          }
          break;
        case FrameInfo::Kind::kSinusoid:
          phase_frames_.push_back(i);
          ws_.push_back(static_cast<float>(std::sin(f.delta)));
          wc_.push_back(static_cast<float>(std::cos(f.delta)));
          break;
        case FrameInfo::Kind::kFlat: break;
      }
    }
    with_phase_ = !phase_frames_.empty();
    if (with_phase_ && !options.projector_response.empty()) {
      std::vector<double> deltas;
      for (std::size_t m = 0; m < ws_.size(); ++m)
        deltas.push_back(std::atan2(static_cast<double>(ws_[m]), static_cast<double>(wc_[m])));
      correction_ = makePhaseCorrection(options.projector_response, spec.offset, spec.amplitude,
                                        deltas, false, "pattern '" + spec.name + "'");
    }
    complementary_ = with_phase_ && spec.complementary;
  }

  int scratchRows() const override { return 6; }

 private:
  friend class RowTemplateCodec<GrayCodec>;

  template <typename Pixel>
  void row(const RowContext& c, const Pixel* const* frames, int width, const RowOutput& out) const {
    const int n = width;
    float* __restrict peak = c.scratch;
    float* __restrict threshold2 = c.scratch + n;  // 2 * threshold (no inverse frames)
    float* __restrict value = c.scratch + 2 * n;   // binary value of the code
    float* __restrict last_bit = c.scratch + 3 * n;
    float* __restrict phase = c.scratch + 4 * n;
    float* __restrict b2 = c.scratch + 5 * n;
    const int count = spec().framesPerDirection();
    for (int x = 0; x < n; ++x) peak[x] = frames[0][x];
    for (int i = 1; i < count; ++i) {
      const Pixel* f = frames[i];
      for (int x = 0; x < n; ++x) peak[x] = std::max(peak[x], static_cast<float>(f[x]));
    }
    const bool inverse = !inverse_.empty();
    float* __restrict a = out.offset;
    float* __restrict b = out.modulation;
    // Contrast from the references, or from the bits and their inverses.
    if (white_ >= 0) {
      const Pixel* w = frames[white_];
      const Pixel* k = frames[black_];
      for (int x = 0; x < n; ++x) {
        const float wv = w[x], kv = k[x];
        a[x] = 0.5f * (wv + kv);
        b[x] = 0.5f * (wv - kv);
        threshold2[x] = wv + kv;
      }
    } else if (!inverse) {
      // Neither references nor inverses (Gray + phase shift only): each bit
      // against the mean A of the phase-shift frames, the level half way
      // between the sinusoid's white and black; B comes from the sinusoid.
      for (int x = 0; x < n; ++x) threshold2[x] = 0.0f;
      for (int m : phase_frames_) {
        const Pixel* f = frames[m];
        for (int x = 0; x < n; ++x) threshold2[x] += f[x];
      }
      const float twice_mean = 2.0f / static_cast<float>(phase_frames_.size());
      for (int x = 0; x < n; ++x) {
        threshold2[x] *= twice_mean;
        a[x] = 0.5f * threshold2[x];
        b[x] = 0.0f;
      }
    } else {
      for (int x = 0; x < n; ++x) a[x] = b[x] = 0.0f;
      for (std::size_t i = 0; i < bits_.size(); ++i) {
        const Pixel* f = frames[bits_[i]];
        const Pixel* g = frames[inverse_[i]];
        for (int x = 0; x < n; ++x) {
          const float fv = f[x], gv = g[x];
          a[x] += fv + gv;
          b[x] = std::max(b[x], std::fabs(fv - gv));
        }
      }
      const float scale = 0.5f / static_cast<float>(bits_.size());
      for (int x = 0; x < n; ++x) {
        a[x] *= scale;
        b[x] *= 0.5f;
      }
    }
    // Gray -> binary, MSB first.
    for (int x = 0; x < n; ++x) value[x] = last_bit[x] = 0.0f;
    for (std::size_t i = 0; i < bits_.size(); ++i) {
      const Pixel* f = frames[bits_[i]];
      const Pixel* g = inverse ? frames[inverse_[i]] : nullptr;
      for (int x = 0; x < n; ++x) {
        const float fv = f[x];
        const bool on = inverse ? fv > static_cast<float>(g[x]) : 2.0f * fv > threshold2[x];
        const float gray = on ? 1.0f : 0.0f;
        const float bin = gray != last_bit[x] ? 1.0f : 0.0f;  // xor
        last_bit[x] = bin;
        value[x] = 2.0f * value[x] + bin;
      }
    }

    const float axis = c.axis_length;
    const float max_coord = axis - 0.5f;
    const float min_b = options().min_modulation * c.dn_scale;
    const float saturation = c.saturation;
    float* __restrict coord = out.coord;
    std::uint8_t* __restrict status = out.status;
    const int axis_px = static_cast<int>(axis);
    if (!with_phase_) {
      const float stripe = static_cast<float>(spec().stripeWidth(axis_px));
      for (int x = 0; x < n; ++x) {
        // Centre of the part of the stripe inside the projector.
        const float start = value[x] * stripe;
        const float end = std::min(start + stripe, axis);
        coord[x] = 0.5f * (start + end) - 0.5f;
        std::uint8_t s = start <= axis - 1.0f ? 0 : 4;
        s = b[x] >= min_b ? s : 1;
        s = peak[x] >= saturation ? 2 : s;
        status[x] = s;
        out.residual[x] = 0.0f;
      }
      return;
    }
    // Phase of the sinusoid (one period per stripe, phase 0 at p = -0.5).
    {
      float* __restrict sv = last_bit;  // reuse
      float* __restrict cv = threshold2;
      for (int x = 0; x < n; ++x) sv[x] = cv[x] = 0.0f;
      for (std::size_t m = 0; m < phase_frames_.size(); ++m) {
        const Pixel* f = frames[phase_frames_[m]];
        const float ws = ws_[m], wc = wc_[m];
        for (int x = 0; x < n; ++x) {
          sv[x] += ws * f[x];
          cv[x] += wc * f[x];
        }
      }
      const float scale = 2.0f / static_cast<float>(phase_frames_.size());
      float* __restrict a_out = out.offset;
      for (int x = 0; x < n; ++x) {
        phase[x] = fastAtan2Positive(sv[x], cv[x]);
        if (correction_) phase[x] = correction_->apply(phase[x]);
        b2[x] = scale * std::sqrt(sv[x] * sv[x] + cv[x] * cv[x]);
        (void)a_out;
      }
      // A and B of the sinusoid replace the Gray contrast.
      for (int x = 0; x < n; ++x) out.modulation[x] = b2[x];
      for (int x = 0; x < n; ++x) a_out[x] = 0.0f;
      for (std::size_t m = 0; m < phase_frames_.size(); ++m) {
        const Pixel* f = frames[phase_frames_[m]];
        for (int x = 0; x < n; ++x) a_out[x] += f[x];
      }
      const float inv = 1.0f / static_cast<float>(phase_frames_.size());
      for (int x = 0; x < n; ++x) a_out[x] *= inv;
    }
    const float period = static_cast<float>(spec().stripeWidth(axis_px));
    const float max_err = options().max_unwrap_error;
    const bool comp = complementary_;
    for (int x = 0; x < n; ++x) {
      const float h = value[x];
      const float ph = phase[x];
      float k, err = 0.0f;
      if (comp) {
        const float k1 = std::floor(0.5f * h);
        const float k2 = std::floor(0.5f * (h + 1.0f));
        k = ph < 0.5f * kPi ? k2 : (ph > 1.5f * kPi ? k2 - 1.0f : k1);
        // Distance (periods) of the phase position from the half stripe h.
        const float q = k + ph * kInvTwoPi;
        err = std::max(std::max(0.5f * h - q, q - 0.5f * (h + 1.0f)), 0.0f);
      } else {
        k = h;
      }
      const float p = (k + ph * kInvTwoPi) * period - 0.5f;
      coord[x] = p;
      std::uint8_t s = p >= -0.5f && p <= max_coord ? 0 : 4;
      s = err > max_err ? 3 : s;
      s = out.modulation[x] >= min_b ? s : 1;
      s = peak[x] >= saturation ? 2 : s;
      status[x] = s;
      out.residual[x] = err;
    }
  }

  int white_ = -1, black_ = -1;
  std::vector<int> bits_, inverse_;  // MSB first
  std::vector<int> phase_frames_;
  std::vector<float> ws_, wc_;
  bool with_phase_ = false;
  bool complementary_ = false;
  std::optional<PhaseCorrection> correction_;  // projector response, when given
};

}  // namespace

std::unique_ptr<Codec> makeGrayCodec(const PatternSpec& spec, const DecoderOptions& options) {
  return std::make_unique<GrayCodec>(spec, options);
}

}  // namespace sl::pipeline::detail
