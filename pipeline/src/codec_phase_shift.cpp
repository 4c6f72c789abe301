// N-step phase shift at any list of frequencies with hierarchical or
// heterodyne temporal unwrapping, and 2+1 (quadrature pair + flat frame).
//
// Per sinusoid set j with frames I_n = A + B cos(phi - delta_n):
//   S = sum_n w_n (I_n - F) sin(delta_n),  C = sum_n (I_n - F) cos(delta_n)
// with F = the flat frame (2+1) or 0 (N-step: the sums of sin and cos
// vanish), so that phi = atan2(S, C) and B = b_scale * |(S, C)|
// (b_scale = 2/N for N equally spaced steps, 1 for a quadrature pair).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numbers>
#include <numeric>
#include <vector>

#include "codec_families.h"
#include "fast_atan2.h"
#include "frame_layout.h"
#include "multiversion.h"

namespace sl::pipeline::detail {

namespace {

constexpr float kTwoPi = 2.0f * std::numbers::pi_v<float>;
constexpr float kInvTwoPi = 1.0f / kTwoPi;

// round(x) for x > -1024 without a libm call (vectorizes on SSE2).
inline float roundUp1024(float x) {
  return static_cast<float>(static_cast<std::int32_t>(x + 1024.5f) - 1024);
}

// floor(x) for x > -1024.
inline float floor1024(float x) {
  return static_cast<float>(static_cast<std::int32_t>(x + 1024.0f) - 1024);
}

// Wrapped phase atan2(S, C) in [0, 2*pi) and the running minimum of B^2.
// Branch-free so that it vectorizes.
void phaseAndModulation(int n, const float* __restrict s, const float* __restrict c, float scale2,
                        float* __restrict phase, float* __restrict b2_min) {
  for (int x = 0; x < n; ++x) {
    const float sv = s[x], cv = c[x];
    phase[x] = fastAtan2Positive(sv, cv);
    b2_min[x] = std::min(b2_min[x], (sv * sv + cv * cv) * scale2);
  }
}

// 8-bit 3-step sets: with sum_n w_n = 0, S and C (and so the wrapped phase
// and B^2) depend only on e1 = I0 - I2 and e2 = I1 - I2, each in [-255, 255].
// One entry per (e1, e2), computed in double: exact atan2 instead of
// fastAtan2Positive (within kFastAtan2MaxError of it), B^2 rounded once.
struct ThreeStepEntry {
  float phase;  // [0, 2*pi)
  float b2;     // B^2, camera DN^2
};
constexpr int kThreeStepSide = 511;
inline int threeStepIndex(int e1, int e2) { return (e1 + 255) * kThreeStepSide + (e2 + 255); }

// The table's gather pass is scalar: it beats the computed kernel's 4-wide
// (SSE2) fast atan2, but not the 8-wide AVX2 variant (measured on 1440 x 1080
// 3+3: decode 7.4 vs 10.2 ms with SSE2, 5.5 vs 4.9 ms with AVX2).
inline bool threeStepTablesPay() {
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
  return !__builtin_cpu_supports("avx2");  // see multiversion.h
#else
  return true;
#endif
}

template <typename SetT>
std::shared_ptr<const std::vector<ThreeStepEntry>> makeThreeStepTable(const SetT& s) {
  auto table = std::make_shared<std::vector<ThreeStepEntry>>(kThreeStepSide * kThreeStepSide);
  // The weights are sin / cos of the deltas rounded to float, as in the row
  // kernels; the third frame's weight is taken as -(w0 + w1) (exact sums vanish).
  const double ws0 = s.ws[0], ws1 = s.ws[1], wc0 = s.wc[0], wc1 = s.wc[1];
  const double scale2 = double(s.b_scale) * s.b_scale;
  for (int e1 = -255; e1 <= 255; ++e1) {
    for (int e2 = -255; e2 <= 255; ++e2) {
      const double sv = ws0 * e1 + ws1 * e2, cv = wc0 * e1 + wc1 * e2;
      double phase = std::atan2(sv, cv);
      if (phase < 0) phase += 2.0 * std::numbers::pi;
      float phase_f = static_cast<float>(phase);
      if (phase_f >= kTwoPi) phase_f = 0.0f;
      (*table)[threeStepIndex(e1, e2)] =
          ThreeStepEntry{phase_f, static_cast<float>((sv * sv + cv * cv) * scale2)};
    }
  }
  return table;
}

class PhaseShiftCodec final : public Codec {
 public:
  PhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options) : Codec(spec, options) {
    const auto all = canonicalFrames(spec);
    const int per_direction = spec.framesPerDirection();
    // Sets from the first direction's frames (both directions share the layout).
    for (double f : spec.frequencies) {
      Set s;
      s.frequency = f;
      sets_.push_back(s);
    }
    for (int i = 0; i < per_direction; ++i) {
      const FrameInfo& fi = all[i];
      if (fi.kind == FrameInfo::Kind::kFlat) {
        flat_ = i;
        continue;
      }
      for (Set& s : sets_) {
        if (s.frequency == fi.frequency) {
          s.frames.push_back(i);
          s.ws.push_back(static_cast<float>(std::sin(fi.delta)));
          s.wc.push_back(static_cast<float>(std::cos(fi.delta)));
        }
      }
    }
    for (Set& s : sets_) {
      s.sum_ws = std::accumulate(s.ws.begin(), s.ws.end(), 0.0f);
      s.sum_wc = std::accumulate(s.wc.begin(), s.wc.end(), 0.0f);
      s.b_scale = flat_ >= 0 ? 1.0f : 2.0f / static_cast<float>(s.frames.size());
    }
    order_.resize(sets_.size());
    std::iota(order_.begin(), order_.end(), 0);
    const bool heterodyne = spec.unwrapping == Unwrapping::kHeterodyne;
    std::sort(order_.begin(), order_.end(), [&](int a, int b) {
      return heterodyne ? sets_[a].frequency > sets_[b].frequency
                        : sets_[a].frequency < sets_[b].frequency;
    });
    finest_ = heterodyne ? order_.front() : order_.back();
    if (heterodyne) {
      // Frequencies of the item-0 beat of each level (level 0 = the finest).
      std::vector<double> level;
      for (int i : order_) level.push_back(sets_[i].frequency);
      chain_frequency_.push_back(level[0]);
      while (level.size() > 1) {
        std::vector<double> next;
        for (std::size_t i = 0; i + 1 < level.size(); ++i) next.push_back(level[i] - level[i + 1]);
        level = next;
        chain_frequency_.push_back(level[0]);
      }
      unit_frequency_ = chain_frequency_.back();
    } else {
      unit_frequency_ = sets_[order_.front()].frequency;
    }
    two_three_step_ = !heterodyne && flat_ < 0 && sets_.size() == 2 &&
                      sets_[0].frames.size() == 3 && sets_[1].frames.size() == 3;
    if (two_three_step_ && threeStepTablesPay()) {
      for (int j = 0; j < 2; ++j) {
        const Set& s = sets_[order_[j]];
        const Set& other = sets_[order_[1 - j]];
        if (j == 1 && s.ws == other.ws && s.wc == other.wc && s.b_scale == other.b_scale) {
          lut_[1] = lut_[0];
        } else {
          lut_[j] = makeThreeStepTable(s);
        }
      }
    }
  }

  int scratchRows() const override { return 6 + 3 * static_cast<int>(sets_.size()); }

 protected:
  void decodeRow8(const RowContext& c, const std::uint8_t* const* frames, int width,
                  const RowOutput& out) const override {
    if (lut_[0]) {
      rowTwoThreeStepTable(c, frames, width, out);
      return;
    }
    row(c, frames, width, out);
  }
  void decodeRow16(const RowContext& c, const std::uint16_t* const* frames, int width,
                   const RowOutput& out) const override {
    row(c, frames, width, out);
  }

 private:
  struct Set {
    double frequency = 0;
    std::vector<int> frames;  // indices among the direction's frames
    std::vector<float> ws, wc;
    float sum_ws = 0, sum_wc = 0, b_scale = 1;
  };

  // Per-row constants of the two-set kernels.
  struct TwoSetConstants {
    float ratio, to_px, period, inv_period, max_coord, min_b2, max_err, saturation;
  };
  TwoSetConstants twoSetConstants(const RowContext& c) const {
    const Set& fine = sets_[order_[1]];
    const Set& coarse = sets_[order_[0]];
    TwoSetConstants k;
    k.ratio = static_cast<float>(fine.frequency / coarse.frequency);
    k.to_px =
        static_cast<float>(c.axis_length / (2.0 * std::numbers::pi * sets_[finest_].frequency));
    k.period = static_cast<float>(c.axis_length / unit_frequency_);
    k.inv_period = 1.0f / k.period;
    k.max_coord = c.axis_length - 0.5f;
    const float min_b = options().min_modulation * c.dn_scale;
    k.min_b2 = min_b * min_b;
    k.max_err = options().max_unwrap_error;
    k.saturation = c.saturation;
    return k;
  }
  // Unwrapping, coordinate and status of one pixel, as the general row does
  // (status as a float code: the loops then vectorize in one width).
  static void twoSetPixel(const TwoSetConstants& k, float phase_fine, float phase_coarse,
                          float b2_min, float peak, float& coord, float& status_code) {
    const float cycles = (k.ratio * phase_coarse - phase_fine) * kInvTwoPi;
    const float n = roundUp1024(cycles);
    const float err = std::fabs(cycles - n);
    float p = (phase_fine + kTwoPi * n) * k.to_px;
    p -= k.period * floor1024(p * k.inv_period);
    float st = p >= -0.5f && p <= k.max_coord ? 0.0f : 4.0f;
    st = err > k.max_err ? 3.0f : st;
    st = b2_min >= k.min_b2 ? st : 1.0f;
    st = peak >= k.saturation ? 2.0f : st;
    status_code = st;
    coord = p;
  }

  // Two 3-step sets, hierarchical (the 3+3 patterns): the general row below
  // fused into one pass per pixel (same operations in the same order) at a
  // fraction of the memory traffic; used for 16-bit frames (8-bit frames
  // take rowTwoThreeStepTable()).
  template <typename Pixel>
  SL_MULTIVERSION void rowTwoThreeStep(const RowContext& c, const Pixel* const* frames, int width,
                                       const RowOutput& out) const {
    const Set& fine = sets_[order_[1]];
    const Set& coarse = sets_[order_[0]];
    const Set& first = sets_[0];  // offset A: mean of the first listed set
    const Pixel* __restrict f0 = frames[fine.frames[0]];
    const Pixel* __restrict f1 = frames[fine.frames[1]];
    const Pixel* __restrict f2 = frames[fine.frames[2]];
    const Pixel* __restrict g0 = frames[coarse.frames[0]];
    const Pixel* __restrict g1 = frames[coarse.frames[1]];
    const Pixel* __restrict g2 = frames[coarse.frames[2]];
    // Offset A from the frames of the set listed first (one of the two),
    // already loaded: the same sum in the same order as from its frames.
    const bool first_is_fine = &first == &fine;
    const float fs0 = fine.ws[0], fs1 = fine.ws[1], fs2 = fine.ws[2];
    const float fc0 = fine.wc[0], fc1 = fine.wc[1], fc2 = fine.wc[2];
    const float gs0 = coarse.ws[0], gs1 = coarse.ws[1], gs2 = coarse.ws[2];
    const float gc0 = coarse.wc[0], gc1 = coarse.wc[1], gc2 = coarse.wc[2];
    const float fine_scale2 = fine.b_scale * fine.b_scale;
    const float coarse_scale2 = coarse.b_scale * coarse.b_scale;
    const float inv_count = 1.0f / 3.0f;
    const TwoSetConstants k = twoSetConstants(c);
    float* __restrict coord = out.coord;
    float* __restrict modulation = out.modulation;
    float* __restrict offset = out.offset;
    float* __restrict status_code = c.scratch;
    // Nine inputs and five outputs exceed GCC's alias-check budget; the rows
    // are distinct buffers (frames vs. maps vs. scratch).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC ivdep
#endif
    for (int x = 0; x < width; ++x) {
      const float a0 = f0[x], a1 = f1[x], a2 = f2[x];
      const float b0 = g0[x], b1 = g1[x], b2 = g2[x];
      const float peak = std::max(std::max(std::max(a0, a1), std::max(a2, b0)), std::max(b1, b2));
      offset[x] = (first_is_fine ? (a0 + a1) + a2 : (b0 + b1) + b2) * inv_count;
      const float sf = fs0 * a0 + fs1 * a1 + fs2 * a2;
      const float cf = fc0 * a0 + fc1 * a1 + fc2 * a2;
      const float sg = gs0 * b0 + gs1 * b1 + gs2 * b2;
      const float cg = gc0 * b0 + gc1 * b1 + gc2 * b2;
      const float b2_fine = (sf * sf + cf * cf) * fine_scale2;
      const float b2_coarse = (sg * sg + cg * cg) * coarse_scale2;
      modulation[x] = std::sqrt(b2_fine);
      twoSetPixel(k, fastAtan2Positive(sf, cf), fastAtan2Positive(sg, cg),
                  std::min(b2_fine, b2_coarse), peak, coord[x], status_code[x]);
    }
    // Separate from the float loop, which then vectorizes in one vector width.
    std::uint8_t* __restrict status = out.status;
    for (int x = 0; x < width; ++x) status[x] = static_cast<std::uint8_t>(status_code[x]);
  }

  // rowTwoThreeStep() for 8-bit frames with the phase and B^2 of each set
  // read from its ThreeStepEntry table: a scalar gather pass, then the rest
  // vectorized. Differs from the general row by the atan2 approximation
  // (< kFastAtan2MaxError) and B^2's rounding (test_codecs compares them).
  SL_MULTIVERSION void rowTwoThreeStepTable(const RowContext& c, const std::uint8_t* const* frames,
                                            int width, const RowOutput& out) const {
    const Set& fine = sets_[order_[1]];
    const Set& coarse = sets_[order_[0]];
    const Set& first = sets_[0];
    const std::uint8_t* __restrict f0 = frames[fine.frames[0]];
    const std::uint8_t* __restrict f1 = frames[fine.frames[1]];
    const std::uint8_t* __restrict f2 = frames[fine.frames[2]];
    const std::uint8_t* __restrict g0 = frames[coarse.frames[0]];
    const std::uint8_t* __restrict g1 = frames[coarse.frames[1]];
    const std::uint8_t* __restrict g2 = frames[coarse.frames[2]];
    const std::uint8_t* __restrict o0 = frames[first.frames[0]];
    const std::uint8_t* __restrict o1 = frames[first.frames[1]];
    const std::uint8_t* __restrict o2 = frames[first.frames[2]];
    const ThreeStepEntry* __restrict table_fine = lut_[1]->data();
    const ThreeStepEntry* __restrict table_coarse = lut_[0]->data();
    float* __restrict status_code = c.scratch;
    float* __restrict phase_fine = status_code + width;
    float* __restrict b2_fine = phase_fine + width;
    float* __restrict phase_coarse = b2_fine + width;
    float* __restrict b2_coarse = phase_coarse + width;
    for (int x = 0; x < width; ++x) {
      const ThreeStepEntry ef = table_fine[threeStepIndex(f0[x] - f2[x], f1[x] - f2[x])];
      const ThreeStepEntry eg = table_coarse[threeStepIndex(g0[x] - g2[x], g1[x] - g2[x])];
      phase_fine[x] = ef.phase;
      b2_fine[x] = ef.b2;
      phase_coarse[x] = eg.phase;
      b2_coarse[x] = eg.b2;
    }
    const float inv_count = 1.0f / 3.0f;
    const TwoSetConstants k = twoSetConstants(c);
    float* __restrict coord = out.coord;
    float* __restrict modulation = out.modulation;
    float* __restrict offset = out.offset;
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC ivdep
#endif
    for (int x = 0; x < width; ++x) {
      const float peak =
          std::max(std::max(std::max(static_cast<float>(f0[x]), static_cast<float>(f1[x])),
                            std::max(static_cast<float>(f2[x]), static_cast<float>(g0[x]))),
                   std::max(static_cast<float>(g1[x]), static_cast<float>(g2[x])));
      offset[x] = ((static_cast<float>(o0[x]) + o1[x]) + o2[x]) * inv_count;
      modulation[x] = std::sqrt(b2_fine[x]);
      twoSetPixel(k, phase_fine[x], phase_coarse[x], std::min(b2_fine[x], b2_coarse[x]), peak,
                  coord[x], status_code[x]);
    }
    std::uint8_t* __restrict status = out.status;
    for (int x = 0; x < width; ++x) status[x] = static_cast<std::uint8_t>(status_code[x]);
  }

  template <typename Pixel>
  SL_MULTIVERSION void row(const RowContext& c, const Pixel* const* frames, int width,
                           const RowOutput& out) const {
    if (two_three_step_) {
      rowTwoThreeStep(c, frames, width, out);
      return;
    }
    const int n = width;
    const int k_sets = static_cast<int>(sets_.size());
    float* scratch = c.scratch;
    auto next = [&]() {
      float* r = scratch;
      scratch += n;
      return r;
    };
    float* __restrict s_acc = next();
    float* __restrict c_acc = next();
    float* __restrict b2_min = next();
    float* __restrict peak = next();
    float* __restrict phi_abs = next();
    float* __restrict err = next();
    std::vector<float*> phase(k_sets), work(k_sets), chain(k_sets);
    for (int j = 0; j < k_sets; ++j) phase[j] = next();
    for (int j = 0; j < k_sets; ++j) work[j] = next();
    for (int j = 0; j < k_sets; ++j) chain[j] = next();

    // Peak over all frames of the direction (saturation test).
    {
      const Pixel* f0 = frames[0];
      for (int x = 0; x < n; ++x) peak[x] = f0[x];
      const int count = static_cast<int>(spec().framesPerDirection());
      for (int i = 1; i < count; ++i) {
        const Pixel* f = frames[i];
        for (int x = 0; x < n; ++x) peak[x] = std::max(peak[x], static_cast<float>(f[x]));
      }
    }
    // Offset A: the flat frame, or the mean of the first listed set.
    {
      float* __restrict a = out.offset;
      if (flat_ >= 0) {
        const Pixel* f = frames[flat_];
        for (int x = 0; x < n; ++x) a[x] = f[x];
      } else {
        const Set& s0 = sets_[0];
        const float inv = 1.0f / static_cast<float>(s0.frames.size());
        const Pixel* f = frames[s0.frames[0]];
        for (int x = 0; x < n; ++x) a[x] = f[x];
        for (std::size_t m = 1; m < s0.frames.size(); ++m) {
          const Pixel* g = frames[s0.frames[m]];
          for (int x = 0; x < n; ++x) a[x] += g[x];
        }
        for (int x = 0; x < n; ++x) a[x] *= inv;
      }
    }
    // Wrapped phase and B^2 of each set.
    for (int x = 0; x < n; ++x) b2_min[x] = std::numeric_limits<float>::max();
    for (int j = 0; j < k_sets; ++j) {
      const Set& s = sets_[j];
      for (int x = 0; x < n; ++x) s_acc[x] = c_acc[x] = 0.0f;
      for (std::size_t m = 0; m < s.frames.size(); ++m) {
        const Pixel* f = frames[s.frames[m]];
        const float ws = s.ws[m], wc = s.wc[m];
        for (int x = 0; x < n; ++x) {
          const float v = f[x];
          s_acc[x] += ws * v;
          c_acc[x] += wc * v;
        }
      }
      if (flat_ >= 0) {
        const Pixel* f = frames[flat_];
        const float ws = s.sum_ws, wc = s.sum_wc;
        for (int x = 0; x < n; ++x) {
          const float v = f[x];
          s_acc[x] -= ws * v;
          c_acc[x] -= wc * v;
        }
      }
      const float scale2 = s.b_scale * s.b_scale;
      phaseAndModulation(n, s_acc, c_acc, scale2, phase[j], b2_min);
      if (j == finest_) {
        float* __restrict b_out = out.modulation;
        for (int x = 0; x < n; ++x)
          b_out[x] = std::sqrt((s_acc[x] * s_acc[x] + c_acc[x] * c_acc[x]) * scale2);
      }
    }

    // Temporal unwrapping -> absolute phase of the finest set in phi_abs.
    for (int x = 0; x < n; ++x) err[x] = 0.0f;
    // In place on phi_abs (read, then overwritten at the same index).
    auto unwrapStep = [&](const float* __restrict fine, float ratio) {
      float* __restrict abs_phase = phi_abs;
      for (int x = 0; x < n; ++x) {
        const float cycles = (ratio * abs_phase[x] - fine[x]) * kInvTwoPi;
        const float k = roundUp1024(cycles);
        err[x] = std::max(err[x], std::fabs(cycles - k));
        abs_phase[x] = fine[x] + kTwoPi * k;
      }
    };
    if (spec().unwrapping == Unwrapping::kHierarchical) {
      std::copy(phase[order_[0]], phase[order_[0]] + n, phi_abs);
      for (int i = 1; i < k_sets; ++i) {
        const float ratio =
            static_cast<float>(sets_[order_[i]].frequency / sets_[order_[i - 1]].frequency);
        unwrapStep(phase[order_[i]], ratio);
      }
    } else {
      // Level 0: phases sorted by descending frequency; each next level holds
      // the wrapped beats of neighbours; chain[l] = item 0 of level l.
      for (int i = 0; i < k_sets; ++i) std::copy(phase[order_[i]], phase[order_[i]] + n, work[i]);
      std::copy(work[0], work[0] + n, chain[0]);
      for (int level = 1; level < k_sets; ++level) {
        for (int i = 0; i + level < k_sets; ++i) {
          float* __restrict a = work[i];
          const float* __restrict b = work[i + 1];
          for (int x = 0; x < n; ++x) {
            const float d = a[x] - b[x];
            a[x] = d < 0.0f ? d + kTwoPi : d;
          }
        }
        std::copy(work[0], work[0] + n, chain[level]);
      }
      std::copy(chain[k_sets - 1], chain[k_sets - 1] + n, phi_abs);
      for (int level = k_sets - 2; level >= 0; --level) {
        const float ratio =
            static_cast<float>(chain_frequency_[level] / chain_frequency_[level + 1]);
        unwrapStep(chain[level], ratio);
      }
    }

    // Coordinate, wrapped into one code period [0, P), and status.
    const float to_px =
        static_cast<float>(c.axis_length / (2.0 * std::numbers::pi * sets_[finest_].frequency));
    const float period = static_cast<float>(c.axis_length / unit_frequency_);
    const float inv_period = 1.0f / period;
    const float max_coord = c.axis_length - 0.5f;
    const float min_b = options().min_modulation * c.dn_scale;
    const float min_b2 = min_b * min_b;
    const float max_err = options().max_unwrap_error;
    const float saturation = c.saturation;
    float* __restrict coord = out.coord;
    std::uint8_t* __restrict status = out.status;
    for (int x = 0; x < n; ++x) {
      float p = phi_abs[x] * to_px;
      p -= period * floor1024(p * inv_period);
      coord[x] = p;
      std::uint8_t s = p >= -0.5f && p <= max_coord ? 0 : 4;
      s = err[x] > max_err ? 3 : s;
      s = b2_min[x] >= min_b2 ? s : 1;
      s = peak[x] >= saturation ? 2 : s;
      status[x] = s;
    }
  }

  std::vector<Set> sets_;                // in listed order
  std::vector<int> order_;               // unwrapping order (see constructor)
  std::vector<double> chain_frequency_;  // heterodyne: item-0 frequency per level
  int finest_ = 0;
  int flat_ = -1;                // 2+1: index of the flat frame
  bool two_three_step_ = false;  // rowTwoThreeStep() applies
  // rowTwoThreeStep() on 8-bit frames without AVX2: tables of the coarse [0]
  // and fine [1] set (one shared table when their weights agree), else null.
  std::shared_ptr<const std::vector<ThreeStepEntry>> lut_[2];
  double unit_frequency_ = 1.0;  // frequency of the coarsest (beat) phase
};

}  // namespace

std::unique_ptr<Codec> makePhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options) {
  return std::make_unique<PhaseShiftCodec>(spec, options);
}

}  // namespace sl::pipeline::detail
