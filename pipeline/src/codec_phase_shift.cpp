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
#include <type_traits>
#include <vector>

#include "codec_families.h"
#include "fast_atan2.h"
#include "phase_response.h"
#include "frame_layout.h"
#include "sl/pipeline/multiversion.h"
#include "two_three_step_row.h"

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#include <immintrin.h>
#define SL_HAVE_AVX512_TWO_THREE_STEP 1
#endif

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

// Unwrapping, coordinate and status of one pixel of two sets, as the general
// row does (status as a float code: the loops then vectorize in one width).
inline void twoSetPixel(const TwoSetConstants& k, float phase_fine, float phase_coarse,
                        float b2_min, float peak, float& coord, float& status_code,
                        float& residual) {
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
  residual = err;
}

// Two 3-step sets, hierarchical (the 3+3 patterns): the general row fused
// into one pass per pixel (same operations in the same order) at a fraction
// of the memory traffic. The offset's source set is a template parameter so
// that the loop has no select on it.
template <bool kOffsetFromFine, typename Pixel>
[[gnu::always_inline]] inline void twoThreeStepLoop(const TwoThreeStepParams& prm,
                                                    const Pixel* const* rows, int width,
                                                    const TwoThreeStepOutput& out) {
  const Pixel* __restrict f0 = rows[0];
  const Pixel* __restrict f1 = rows[1];
  const Pixel* __restrict f2 = rows[2];
  const Pixel* __restrict g0 = rows[3];
  const Pixel* __restrict g1 = rows[4];
  const Pixel* __restrict g2 = rows[5];
  const float fs0 = prm.fine.ws[0], fs1 = prm.fine.ws[1], fs2 = prm.fine.ws[2];
  const float fc0 = prm.fine.wc[0], fc1 = prm.fine.wc[1], fc2 = prm.fine.wc[2];
  const float gs0 = prm.coarse.ws[0], gs1 = prm.coarse.ws[1], gs2 = prm.coarse.ws[2];
  const float gc0 = prm.coarse.wc[0], gc1 = prm.coarse.wc[1], gc2 = prm.coarse.wc[2];
  const float fine_scale2 = prm.fine.scale2;
  const float coarse_scale2 = prm.coarse.scale2;
  const float inv_count = 1.0f / 3.0f;
  const TwoSetConstants k = prm.k;
  float* __restrict coord = out.coord;
  float* __restrict modulation = out.modulation;
  float* __restrict offset = out.offset;
  float* __restrict residual = out.residual;
  float* __restrict status_code = out.scratch;
  // Nine inputs and five outputs exceed GCC's alias-check budget; the rows
  // are distinct buffers (frames vs. maps vs. scratch).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC ivdep
#endif
  for (int x = 0; x < width; ++x) {
    const float a0 = f0[x], a1 = f1[x], a2 = f2[x];
    const float b0 = g0[x], b1 = g1[x], b2 = g2[x];
    const float peak = std::max(std::max(std::max(a0, a1), std::max(a2, b0)), std::max(b1, b2));
    offset[x] = (kOffsetFromFine ? (a0 + a1) + a2 : (b0 + b1) + b2) * inv_count;
    const float sf = fs0 * a0 + fs1 * a1 + fs2 * a2;
    const float cf = fc0 * a0 + fc1 * a1 + fc2 * a2;
    const float sg = gs0 * b0 + gs1 * b1 + gs2 * b2;
    const float cg = gc0 * b0 + gc1 * b1 + gc2 * b2;
    const float b2_fine = (sf * sf + cf * cf) * fine_scale2;
    const float b2_coarse = (sg * sg + cg * cg) * coarse_scale2;
    modulation[x] = std::sqrt(b2_fine);
    twoSetPixel(k, fastAtan2Positive(sf, cf), fastAtan2Positive(sg, cg),
                std::min(b2_fine, b2_coarse), peak, coord[x], status_code[x], residual[x]);
  }
  // Separate from the float loop, which then vectorizes in one vector width.
  std::uint8_t* __restrict status = out.status;
  for (int x = 0; x < width; ++x) status[x] = static_cast<std::uint8_t>(status_code[x]);
}

template <typename Pixel>
SL_MULTIVERSION void twoThreeStepRowAnyIsa(const TwoThreeStepParams& p, const Pixel* const* rows,
                                           int width, const TwoThreeStepOutput& out) {
  if (p.offset_from_fine) {
    twoThreeStepLoop<true>(p, rows, width, out);
  } else {
    twoThreeStepLoop<false>(p, rows, width, out);
  }
}

}  // namespace

void twoThreeStepRow(const TwoThreeStepParams& p, const std::uint8_t* const* rows, int width,
                     const TwoThreeStepOutput& out) {
  twoThreeStepRowAnyIsa(p, rows, width, out);
}

void twoThreeStepRow(const TwoThreeStepParams& p, const std::uint16_t* const* rows, int width,
                     const TwoThreeStepOutput& out) {
  twoThreeStepRowAnyIsa(p, rows, width, out);
}

#if defined(SL_HAVE_AVX512_TWO_THREE_STEP)

// twoThreeStepLoop() for 8-bit rows written with AVX-512 intrinsics: the
// same IEEE operations in the same order (separate multiply and add, never
// FMA), so the results are identical; test_decoder compares the two. What it
// saves over the compiled loop: GCC vectorizes that loop 64 pixels (one byte
// vector) at a time, i.e. four float vectors that overflow the registers,
// converts bytes in two steps, and selects with compare + blend. Here each
// step handles kLanes vectors of 16 pixels in turn (independent chains for
// out-of-order execution without spills), selects with masked operations,
// takes the peak and status in bytes, and writes the status directly.
// Results are bit for bit those of the portable row; it is faster (no float
// status row to write and read back; bench_codecs, figures in
// docs/measurements.md).
namespace {

#define SL_AVX512 __attribute__((target("avx512f,avx512bw,avx512vl")))
// GCC 12's AVX-512 intrinsics start from an undefined register and trip
// -W(maybe-)uninitialized when inlined (false positives; in sanitizer builds
// also in the helpers below, up to the pop after twoThreeStepRowAvx512).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
// Each statement of the kernel below over the kLanes vectors in flight.
#define SL_EACH_LANE _Pragma("GCC unroll 8") for (int j = 0; j < N; ++j)

struct Avx512Constants {
  __m512 poly[7];
  __m512 half_pi, pi, two_pi, zero;
  __m512 fs[3], fc[3], gs[3], gc[3], fine_scale2, coarse_scale2, inv_count;
  __m512 ratio, inv_two_pi, bias_round, bias_floor, k1024, to_px, period, inv_period;
  __m512 min_coord, max_coord, max_err, min_b2;
  __m512i abs_mask;
  __m128i saturated_from;        // peak byte >= this: saturated
  __mmask16 saturation_enabled;  // all ones, or 0 when saturation > 255
  bool offset_from_fine;
};

struct Avx512Rows {
  const std::uint8_t* in[6];
  float* coord;
  float* modulation;
  float* offset;
  std::uint8_t* status;
  float* residual;
};

SL_AVX512 inline __m512 absPs(__m512 v, __m512i abs_mask) {
  return _mm512_castsi512_ps(_mm512_and_si512(_mm512_castps_si512(v), abs_mask));
}

// w0 * v0 + w1 * v1 + w2 * v2, left to right.
SL_AVX512 inline __m512 dot3(const __m512* w, __m512 v0, __m512 v1, __m512 v2) {
  return _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(w[0], v0), _mm512_mul_ps(w[1], v1)),
                       _mm512_mul_ps(w[2], v2));
}

// roundUp1024() / floor1024(): float(int32(v + bias) - 1024). Truncation
// of the float (roundscale) then subtracting 1024.0f gives the same value in
// fewer operations: both are exact for |v + bias| < 2^24.
SL_AVX512 inline __m512 truncBiased(__m512 v, __m512 bias, __m512 k1024) {
  return _mm512_sub_ps(
      _mm512_roundscale_ps(_mm512_add_ps(v, bias), _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC), k1024);
}

// fastAtan2Positive() of N vectors.
template <int N>
SL_AVX512 inline void fastAtan2PositiveN(const Avx512Constants& c, const __m512* y, const __m512* x,
                                         __m512* r) {
  __m512 ax[N], ay[N], a[N], s[N], q[N];
  SL_EACH_LANE {
    ax[j] = absPs(x[j], c.abs_mask);
    ay[j] = absPs(y[j], c.abs_mask);
  }
  SL_EACH_LANE {
    // max / min return their second operand unless the first is greater /
    // smaller: ax > ay ? ax : ay and ax > ay ? ay : ax as in the scalar code.
    const __m512 hi = _mm512_max_ps(ax[j], ay[j]);
    const __m512 lo = _mm512_min_ps(ay[j], ax[j]);
    // lo / hi, or lo / 1 = +0 when hi = 0.
    a[j] = _mm512_maskz_div_ps(_mm512_cmp_ps_mask(hi, c.zero, _CMP_GT_OQ), lo, hi);
  }
  SL_EACH_LANE s[j] = _mm512_mul_ps(a[j], a[j]);
  SL_EACH_LANE q[j] = _mm512_add_ps(c.poly[5], _mm512_mul_ps(s[j], c.poly[6]));
  for (int i = 4; i >= 0; --i) {
    SL_EACH_LANE q[j] = _mm512_add_ps(c.poly[i], _mm512_mul_ps(s[j], q[j]));
  }
  SL_EACH_LANE r[j] = _mm512_mul_ps(a[j], q[j]);
  SL_EACH_LANE r[j] =
      _mm512_mask_sub_ps(r[j], _mm512_cmp_ps_mask(ay[j], ax[j], _CMP_GT_OQ), c.half_pi, r[j]);
  SL_EACH_LANE r[j] =
      _mm512_mask_sub_ps(r[j], _mm512_cmp_ps_mask(x[j], c.zero, _CMP_LT_OQ), c.pi, r[j]);
  SL_EACH_LANE r[j] =
      _mm512_mask_sub_ps(r[j], _mm512_cmp_ps_mask(y[j], c.zero, _CMP_LT_OQ), c.two_pi, r[j]);
  SL_EACH_LANE r[j] = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask(r[j], c.two_pi, _CMP_NGE_UQ), r[j]);
}

// Pixels [x, x + 16 N) (lanes outside `m` neither read nor written).
template <int N>
SL_AVX512 inline void twoThreeStepBlock(const Avx512Constants& c, const Avx512Rows& r, int x,
                                        __mmask16 m) {
  __m512 in[6][N];
  __m128i peak[N];
  SL_EACH_LANE {
    __m128i bytes[6];
    for (int i = 0; i < 6; ++i) {
      bytes[i] = _mm_maskz_loadu_epi8(m, r.in[i] + x + 16 * j);
      in[i][j] = _mm512_cvtepi32_ps(_mm512_cvtepu8_epi32(bytes[i]));
    }
    peak[j] = _mm_max_epu8(
        _mm_max_epu8(_mm_max_epu8(bytes[0], bytes[1]), _mm_max_epu8(bytes[2], bytes[3])),
        _mm_max_epu8(bytes[4], bytes[5]));
  }
  SL_EACH_LANE {
    const __m512 sum = c.offset_from_fine
                           ? _mm512_add_ps(_mm512_add_ps(in[0][j], in[1][j]), in[2][j])
                           : _mm512_add_ps(_mm512_add_ps(in[3][j], in[4][j]), in[5][j]);
    _mm512_mask_storeu_ps(r.offset + x + 16 * j, m, _mm512_mul_ps(sum, c.inv_count));
  }
  __m512 sf[N], cf[N], sg[N], cg[N], b2_fine[N], b2_coarse[N];
  SL_EACH_LANE {
    sf[j] = dot3(c.fs, in[0][j], in[1][j], in[2][j]);
    cf[j] = dot3(c.fc, in[0][j], in[1][j], in[2][j]);
    sg[j] = dot3(c.gs, in[3][j], in[4][j], in[5][j]);
    cg[j] = dot3(c.gc, in[3][j], in[4][j], in[5][j]);
  }
  SL_EACH_LANE {
    b2_fine[j] = _mm512_mul_ps(
        _mm512_add_ps(_mm512_mul_ps(sf[j], sf[j]), _mm512_mul_ps(cf[j], cf[j])), c.fine_scale2);
    b2_coarse[j] = _mm512_mul_ps(
        _mm512_add_ps(_mm512_mul_ps(sg[j], sg[j]), _mm512_mul_ps(cg[j], cg[j])), c.coarse_scale2);
  }
  SL_EACH_LANE _mm512_mask_storeu_ps(r.modulation + x + 16 * j, m, _mm512_sqrt_ps(b2_fine[j]));
  __m512 phase_fine[N], phase_coarse[N];
  fastAtan2PositiveN<N>(c, sf, cf, phase_fine);
  fastAtan2PositiveN<N>(c, sg, cg, phase_coarse);
  // twoSetPixel().
  __m512 cycles[N], n[N], p[N];
  SL_EACH_LANE cycles[j] = _mm512_mul_ps(
      _mm512_sub_ps(_mm512_mul_ps(c.ratio, phase_coarse[j]), phase_fine[j]), c.inv_two_pi);
  SL_EACH_LANE n[j] = truncBiased(cycles[j], c.bias_round, c.k1024);
  SL_EACH_LANE p[j] =
      _mm512_mul_ps(_mm512_add_ps(phase_fine[j], _mm512_mul_ps(c.two_pi, n[j])), c.to_px);
  SL_EACH_LANE p[j] = _mm512_sub_ps(
      p[j], _mm512_mul_ps(c.period,
                          truncBiased(_mm512_mul_ps(p[j], c.inv_period), c.bias_floor, c.k1024)));
  SL_EACH_LANE _mm512_mask_storeu_ps(r.coord + x + 16 * j, m, p[j]);
  SL_EACH_LANE {
    const __m512 err = absPs(_mm512_sub_ps(cycles[j], n[j]), c.abs_mask);
    _mm512_mask_storeu_ps(r.residual + x + 16 * j, m, err);
    const __mmask16 in_range = _mm512_mask_cmp_ps_mask(
        _mm512_cmp_ps_mask(p[j], c.min_coord, _CMP_GE_OQ), p[j], c.max_coord, _CMP_LE_OQ);
    const __mmask16 bad_unwrap = _mm512_cmp_ps_mask(err, c.max_err, _CMP_GT_OQ);
    const __mmask16 low =
        _mm512_cmp_ps_mask(_mm512_min_ps(b2_coarse[j], b2_fine[j]), c.min_b2, _CMP_NGE_UQ);
    const __mmask16 saturated =
        _mm_mask_cmpge_epu8_mask(c.saturation_enabled, peak[j], c.saturated_from);
    __m128i st = _mm_maskz_mov_epi8(static_cast<__mmask16>(~in_range), _mm_set1_epi8(4));
    st = _mm_mask_mov_epi8(st, bad_unwrap, _mm_set1_epi8(3));
    st = _mm_mask_mov_epi8(st, low, _mm_set1_epi8(1));
    st = _mm_mask_mov_epi8(st, saturated, _mm_set1_epi8(2));
    _mm_mask_storeu_epi8(r.status + x + 16 * j, m, st);
  }
}

}  // namespace

SL_AVX512 void twoThreeStepRowAvx512(const TwoThreeStepParams& prm, const std::uint8_t* const* rows,
                                     int width, const TwoThreeStepOutput& out) {
  Avx512Constants c;
  for (int i = 0; i < 7; ++i) c.poly[i] = _mm512_set1_ps(kFastAtanPoly[i]);
  constexpr float kPi = std::numbers::pi_v<float>;
  c.half_pi = _mm512_set1_ps(0.5f * kPi);
  c.pi = _mm512_set1_ps(kPi);
  c.two_pi = _mm512_set1_ps(2.0f * kPi);
  c.zero = _mm512_setzero_ps();
  for (int i = 0; i < 3; ++i) {
    c.fs[i] = _mm512_set1_ps(prm.fine.ws[i]);
    c.fc[i] = _mm512_set1_ps(prm.fine.wc[i]);
    c.gs[i] = _mm512_set1_ps(prm.coarse.ws[i]);
    c.gc[i] = _mm512_set1_ps(prm.coarse.wc[i]);
  }
  c.fine_scale2 = _mm512_set1_ps(prm.fine.scale2);
  c.coarse_scale2 = _mm512_set1_ps(prm.coarse.scale2);
  c.inv_count = _mm512_set1_ps(1.0f / 3.0f);
  const TwoSetConstants& k = prm.k;
  c.ratio = _mm512_set1_ps(k.ratio);
  c.inv_two_pi = _mm512_set1_ps(kInvTwoPi);
  c.bias_round = _mm512_set1_ps(1024.5f);
  c.bias_floor = _mm512_set1_ps(1024.0f);
  c.k1024 = _mm512_set1_ps(1024.0f);
  c.to_px = _mm512_set1_ps(k.to_px);
  c.period = _mm512_set1_ps(k.period);
  c.inv_period = _mm512_set1_ps(k.inv_period);
  c.min_coord = _mm512_set1_ps(-0.5f);
  c.max_coord = _mm512_set1_ps(k.max_coord);
  c.max_err = _mm512_set1_ps(k.max_err);
  c.min_b2 = _mm512_set1_ps(k.min_b2);
  c.abs_mask = _mm512_set1_epi32(0x7fffffff);
  // peak >= saturation for a byte peak: peak >= ceil(saturation) when
  // saturation <= 255, never when it is larger (+inf: not rejecting).
  const bool can_saturate = k.saturation <= 255.0f;
  const int saturated_from =
      can_saturate ? static_cast<int>(std::ceil(std::max(k.saturation, 0.0f))) : 0;
  c.saturated_from = _mm_set1_epi8(static_cast<char>(saturated_from));
  c.saturation_enabled = can_saturate ? 0xffff : 0;
  c.offset_from_fine = prm.offset_from_fine;
  const Avx512Rows r{{rows[0], rows[1], rows[2], rows[3], rows[4], rows[5]},
                     out.coord,
                     out.modulation,
                     out.offset,
                     out.status,
                     out.residual};
  // Vectors in flight: with 1 the kernel was slower than the compiled loop,
  // with 2 about as fast; 3 and 4 measured alike.
  constexpr int kLanes = 4;
  int x = 0;
  for (; x + 16 * kLanes <= width; x += 16 * kLanes) twoThreeStepBlock<kLanes>(c, r, x, 0xffff);
  for (; x < width; x += 16) {
    const int left = width - x;
    twoThreeStepBlock<1>(c, r, x, left >= 16 ? 0xffff : static_cast<__mmask16>((1u << left) - 1));
  }
}
#pragma GCC diagnostic pop

bool twoThreeStepAvx512Supported() {
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512vl");
}

#undef SL_EACH_LANE
#undef SL_AVX512

#else

bool twoThreeStepAvx512Supported() { return false; }

void twoThreeStepRowAvx512(const TwoThreeStepParams& p, const std::uint8_t* const* rows, int width,
                           const TwoThreeStepOutput& out) {
  twoThreeStepRow(p, rows, width, out);
}

#endif

namespace {

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
// (SSE2) fast atan2, but not the 8-wide AVX2 variant (bench_codecs,
// docs/measurements.md).
inline bool threeStepTablesPay() {
#if SL_MULTIVERSION_ENABLED
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

class PhaseShiftCodec final : public RowTemplateCodec<PhaseShiftCodec> {
 public:
  PhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options)
      : RowTemplateCodec(spec, options) {
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
    if (!options.projector_response.empty()) {
      // Compensation: each set's phase through its table, in the general row.
      for (const Set& s : sets_) {
        std::vector<double> deltas;
        for (std::size_t m = 0; m < s.ws.size(); ++m)
          deltas.push_back(std::atan2(static_cast<double>(s.ws[m]), static_cast<double>(s.wc[m])));
        corrections_.push_back(makePhaseCorrection(options.projector_response, spec.offset,
                                                   spec.amplitude, deltas, flat_ >= 0,
                                                   "pattern '" + spec.name + "'"));
      }
    }
    two_three_step_ = corrections_.empty() && !heterodyne && flat_ < 0 && sets_.size() == 2 &&
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
 private:
  friend class RowTemplateCodec<PhaseShiftCodec>;

  struct Set {
    double frequency = 0;
    std::vector<int> frames;  // indices among the direction's frames
    std::vector<float> ws, wc;
    float sum_ws = 0, sum_wc = 0, b_scale = 1;
  };

  // Per-row constants of the two-set kernels.
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
  // Two 3-step sets, hierarchical (the 3+3 patterns): twoThreeStepRow(), or
  // its AVX-512 form for 8-bit frames where the CPU has it.
  template <typename Pixel>
  void rowTwoThreeStep(const RowContext& c, const Pixel* const* frames, int width,
                       const RowOutput& out) const {
    const Set& fine = sets_[order_[1]];
    const Set& coarse = sets_[order_[0]];
    TwoThreeStepParams p;
    for (int n = 0; n < 3; ++n) {
      p.fine.ws[n] = fine.ws[n];
      p.fine.wc[n] = fine.wc[n];
      p.coarse.ws[n] = coarse.ws[n];
      p.coarse.wc[n] = coarse.wc[n];
    }
    p.fine.scale2 = fine.b_scale * fine.b_scale;
    p.coarse.scale2 = coarse.b_scale * coarse.b_scale;
    // Offset A: the mean of the set listed first (one of the two).
    p.offset_from_fine = &sets_[0] == &fine;
    p.k = twoSetConstants(c);
    const Pixel* rows[6] = {frames[fine.frames[0]],   frames[fine.frames[1]],
                            frames[fine.frames[2]],   frames[coarse.frames[0]],
                            frames[coarse.frames[1]], frames[coarse.frames[2]]};
    const TwoThreeStepOutput o{out.coord,  out.modulation, out.offset,
                               out.status, out.residual,   c.scratch};
    if constexpr (std::is_same_v<Pixel, std::uint8_t>) {
      if (avx512_) {
        twoThreeStepRowAvx512(p, rows, width, o);
        return;
      }
    }
    twoThreeStepRow(p, rows, width, o);
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
    float* __restrict residual = out.residual;
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
                  coord[x], status_code[x], residual[x]);
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
      if (!corrections_.empty()) {
        const PhaseCorrection& table = corrections_[j];
        float* __restrict ph = phase[j];
        for (int x = 0; x < n; ++x) ph[x] = table.apply(ph[x]);
      }
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
    std::copy(err, err + n, out.residual);
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
  bool avx512_ = twoThreeStepAvx512Supported();
  // rowTwoThreeStep() on 8-bit frames without AVX2: tables of the coarse [0]
  // and fine [1] set (one shared table when their weights agree), else null.
  std::shared_ptr<const std::vector<ThreeStepEntry>> lut_[2];
  double unit_frequency_ = 1.0;  // frequency of the coarsest (beat) phase
  // Per set (listed order): the projector-response correction, or empty.
  std::vector<PhaseCorrection> corrections_;
};

}  // namespace

std::unique_ptr<Codec> makePhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options) {
  return std::make_unique<PhaseShiftCodec>(spec, options);
}

}  // namespace sl::pipeline::detail
