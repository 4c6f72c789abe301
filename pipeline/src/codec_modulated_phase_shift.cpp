// Modulated phase shifting (Chen, Stewart, Yang, "Modulated phase-shifting
// for 3D scanning", CVPR 2008): every phase-shift frame is multiplied by a
// high-frequency carrier along the other projector axis, projected at three
// carrier shifts. Light that reaches a pixel directly keeps the carrier;
// interreflections and subsurface scattering mix many carrier phases and
// lose it. Per pixel and phase step the carrier's amplitude over its three
// shifts is the direct part of the sinusoid at that step (up to the pixel's
// gain); the N-step phase of those amplitudes, unwrapped hierarchically as
// for phase_shift, is the coordinate.
//
// Frames per direction: for each frequency (listed order), for each step n,
// the three carrier shifts m = 0, 1, 2 (carrier 0.5 + 0.5 cos(2 pi q /
// carrier_pitch - 2 pi m / 3), q the other axis' coordinate); a set without
// carrier (PatternSpec::modulated_sets) has one frame per step, whose
// intensity (direct and global light) stands for the direct part.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "codec_families.h"
#include "fast_atan2.h"
#include "frame_layout.h"
#include "phase_response.h"

namespace sl::pipeline::detail {

namespace {

constexpr float kTwoPi = 2.0f * std::numbers::pi_v<float>;
constexpr float kInvTwoPi = 1.0f / kTwoPi;

class ModulatedPhaseShiftCodec final : public RowTemplateCodec<ModulatedPhaseShiftCodec> {
 public:
  ModulatedPhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options)
      : RowTemplateCodec(spec, options) {
    if (!options.projector_response.empty())
      throw std::invalid_argument("pattern '" + spec.name +
                                  "': projector_response compensation is not implemented for "
                                  "modulated_phase_shift");
    const auto frames = canonicalFrames(spec);
    const int sets = static_cast<int>(spec.frequencies.size());
    const int steps = spec.steps;
    int first = 0, modulated_first = -1;
    for (int j = 0; j < sets; ++j) {
      Set s;
      s.frequency = spec.frequencies[j];
      s.first = first;
      s.carriers = spec.setModulated(static_cast<std::size_t>(j)) ? 3 : 1;
      if (s.carriers == 3 && modulated_first < 0) modulated_first = first;
      for (int n = 0; n < steps; ++n) {
        const FrameInfo& f = frames[static_cast<std::size_t>(first + n * s.carriers)];
        s.ws.push_back(static_cast<float>(std::sin(f.delta)));
        s.wc.push_back(static_cast<float>(std::cos(f.delta)));
      }
      first += steps * s.carriers;
      sets_.push_back(s);
    }
    for (int m = 0; m < 3; ++m) {
      const double shift = frames[static_cast<std::size_t>(modulated_first + m)].carrier_shift;
      carrier_ws_[m] = static_cast<float>(std::sin(shift));
      carrier_wc_[m] = static_cast<float>(std::cos(shift));
    }
    order_.resize(sets);
    std::iota(order_.begin(), order_.end(), 0);
    std::sort(order_.begin(), order_.end(),
              [&](int a, int b) { return sets_[a].frequency < sets_[b].frequency; });
  }

  int scratchRows() const override { return 0; }

 private:
  friend class RowTemplateCodec<ModulatedPhaseShiftCodec>;

  struct Set {
    double frequency = 0;
    int first = 0;     // frame of step 0 within the direction
    int carriers = 3;  // frames per step: 3 carrier shifts, or 1 without carrier
    std::vector<float> ws, wc;
  };

  template <typename Pixel>
  void row(const RowContext& c, const Pixel* const* frames, int width, const RowOutput& out) const {
    const int sets = static_cast<int>(sets_.size());
    const int steps = spec().steps;
    const int count = spec().framesPerDirection();
    const float min_b = options().min_modulation * c.dn_scale;
    const float max_err = options().max_unwrap_error;
    const float max_coord = c.axis_length - 0.5f;
    const int finest = order_.back();
    const float to_px =
        static_cast<float>(c.axis_length / (2.0 * std::numbers::pi * sets_[finest].frequency));
    const float period = static_cast<float>(c.axis_length / sets_[order_.front()].frequency);
    std::vector<float> phase(sets), direct(static_cast<std::size_t>(steps));
    for (int x = 0; x < width; ++x) {
      float peak = 0;
      for (int i = 0; i < count; ++i) peak = std::max(peak, static_cast<float>(frames[i][x]));
      float b_min = std::numeric_limits<float>::max(), a_first = 0, b_finest = 0;
      for (int j = 0; j < sets; ++j) {
        const Set& s = sets_[j];
        float ps = 0, pc = 0, sum = 0;
        for (int n = 0; n < steps; ++n) {
          const int first = s.first + n * s.carriers;
          float d = frames[first][x];
          if (s.carriers == 3) {
            float cs = 0, cc = 0;
            for (int m = 0; m < 3; ++m) {
              const float v = frames[first + m][x];
              cs += carrier_ws_[m] * v;
              cc += carrier_wc_[m] * v;
            }
            // Carrier amplitude: (2/3) |(cs, cc)| = half the direct intensity.
            d = (4.0f / 3.0f) * std::sqrt(cs * cs + cc * cc);
          }
          ps += s.ws[n] * d;
          pc += s.wc[n] * d;
          sum += d;
        }
        phase[j] = fastAtan2Positive(ps, pc);
        const float b = 2.0f / static_cast<float>(steps) * std::sqrt(ps * ps + pc * pc);
        b_min = std::min(b_min, b);
        if (j == 0) a_first = sum / static_cast<float>(steps);
        if (j == finest) b_finest = b;
      }
      // Hierarchical unwrapping, as phase_shift's general row.
      float absolute = phase[order_[0]], err = 0;
      for (int i = 1; i < sets; ++i) {
        const float ratio =
            static_cast<float>(sets_[order_[i]].frequency / sets_[order_[i - 1]].frequency);
        const float fine = phase[order_[i]];
        const float cycles = (ratio * absolute - fine) * kInvTwoPi;
        const float k = std::round(cycles);
        err = std::max(err, std::fabs(cycles - k));
        absolute = fine + kTwoPi * k;
      }
      float p = absolute * to_px;
      p -= period * std::floor(p / period);
      out.coord[x] = p;
      out.offset[x] = a_first;
      out.modulation[x] = b_finest;
      out.residual[x] = err;
      std::uint8_t st = p >= -0.5f && p <= max_coord ? 0 : 4;
      st = err > max_err ? 3 : st;
      st = b_min >= min_b ? st : 1;
      st = peak >= c.saturation ? 2 : st;
      out.status[x] = st;
    }
  }

  std::vector<Set> sets_;
  std::vector<int> order_;  // ascending frequency
  float carrier_ws_[3]{}, carrier_wc_[3]{};
};

}  // namespace

std::unique_ptr<Codec> makeModulatedPhaseShiftCodec(const PatternSpec& spec,
                                                    const DecoderOptions& options) {
  return std::make_unique<ModulatedPhaseShiftCodec>(spec, options);
}

}  // namespace sl::pipeline::detail
