#include "sl/pipeline/triangulator.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "sl/pipeline/multiversion.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#include <immintrin.h>
#define SL_HAVE_AVX512_POINTS 1
#ifndef SL_EPIPOLAR_LANES
#define SL_EPIPOLAR_LANES 4
#endif
#endif

namespace sl::pipeline {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Depth along the ray for projector coordinate p, with a = M3[0:3].r,
// b = M[axis][0:3].r and m_axis = M[axis][3]; NaN for NaN input, a ray
// parallel to the projector plane (den ~ 0 gives an infinite or huge z) and
// depths outside [min_z, max_z]. Every row form uses this (the same bits).
inline float depthAlongRay(float p, float a, float b, float m_axis, float m3, float min_z,
                           float max_z) {
  const float den = p * a - b;
  const float z = (m_axis - p * m3) / den;
  const bool valid = (std::abs(den) > 1e-12f) & (z >= min_z) & (z <= max_z);
  return valid ? z : kNaN;
}

// Constants of the epipolar projector-distortion correction for one decoded
// axis ("along"; "other" is the projector's other axis), in single
// precision. M = K_p [R | t] (projector px), distortion coefficients k1, k2,
// k3 (radial) and the tangential pair in the order that makes the distorted
// normalized coordinate along the axis
//   a (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 t1 a o + t2 (r^2 + 2 a^2),
// (a, o) the undistorted normalized coordinates along and across the axis
// (columns: t1 = p1, t2 = p2; rows: t1 = p2, t2 = p1).
//
// The epipolar line of the ray r = (x, y, 1) in the projector's normalized
// image is la a + lo o + lc = 0 with la, lo, lc linear in r: the line
// through the camera centre's image M[0:3][3] and the ray's vanishing point
// M[0:3][0:3] r (their cross product, taken to normalized coordinates),
// its coefficients formed in double from M and K_p.
struct EpipolarAxis {
  float m_along, m3;  // M[along][3], M[2][3]
  float la[3], lo[3], lc[3];
  float f_along, c_along, inv_f_along;
  float k1, k2, k3, two_k2, three_k3;
  float two_t1, t2;
};

// The undistorted projector coordinate (px along the axis) whose distorted
// position is `decoded`, on the epipolar line of the ray (x, y, 1), solved
// for o = alpha + beta a (one division per pixel). On it the
// distorted coordinate is a polynomial g(a) + decoded in a alone: the first
// iteration shifts by g at the decoded coordinate (the same point and shift
// as kAlongRay's first step), later ones are
// secant steps where the secant's slope is sane (0.5 .. 1.5), plain shifts
// elsewhere. Iterations: kIterations, or `iterations` when it is -1. NaN
// where the line is degenerate (parallel to the other axis: the coordinate
// does not change along the ray, so depth is undetermined). The AVX-512 row
// does the same operations in the same order.
template <int kIterations>
inline float epipolarCoordinate(const EpipolarAxis& k, float x, float y, float decoded,
                                int iterations) {
  const float la = k.la[0] * x + k.la[1] * y + k.la[2];
  const float lo = k.lo[0] * x + k.lo[1] * y + k.lo[2];
  const float lc = k.lc[0] * x + k.lc[1] * y + k.lc[2];
  const float inv = -1.0f / lo;
  const float alpha = lc * inv, beta = la * inv;
  const float target = (decoded - k.c_along) * k.inv_f_along;
  float a = target, a_prev = 0.0f, g_prev = 0.0f;
  const int n = kIterations >= 0 ? kIterations : iterations;
  for (int it = 0; it < n; ++it) {
    const float o = alpha + beta * a;
    const float aa = a * a;
    const float r2 = aa + o * o;
    const float radial = r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
    const float shift = (a * radial + k.two_t1 * (a * o)) + k.t2 * (r2 + 2.0f * aa);
    // a = target at the first iteration: g = shift (the same bits).
    const float g = it == 0 ? shift : (a - target) + shift;
    float step = g;
    if (it > 0) {
      // Slope dg / da within 0.5 of 1 (false for da = 0 or NaN).
      const float dg = g - g_prev, da = a - a_prev;
      const bool sane = std::abs(dg - da) < 0.5f * std::abs(da);
      const float secant = g * da / dg;
      step = sane ? secant : g;
    }
    a_prev = a;
    g_prev = g;
    a = a - step;
  }
  return k.f_along * a + k.c_along;
}

// The depth of a pixel with the epipolar correction: depthAlongRay() of the
// corrected coordinate.
// ai = M3[0:3].r, q_along = M[along][0:3].r.
template <int kIterations>
inline float epipolarDepth(const EpipolarAxis& k, float x, float y, float ai, float q_along,
                           float decoded, int iterations, float min_z, float max_z) {
  const float p = epipolarCoordinate<kIterations>(k, x, y, decoded, iterations);
  return depthAlongRay(p, ai, q_along, k.m_along, k.m3, min_z, max_z);
}

// The row loops read and write distinct buffers (maps, rays, scratch, cloud);
// GCC does not always prove it (too many pointers for its alias checks).
#if defined(__GNUC__) && !defined(__clang__)
#define SL_ROW_LOOP _Pragma("GCC ivdep")
#else
#define SL_ROW_LOOP
#endif

// Which projector coordinate constrains a pixel.
enum Axis { kColumn = 0, kRow = 1 };

#if defined(SL_HAVE_AVX512_POINTS)
// Points (z rx, z ry, z, intensity) for pixels [0, n) of a row, 16 per
// iteration with 64-byte non-temporal stores (one cache line = 4 points);
// `out` must be 64-byte aligned. Returns the pixels written (a multiple of
// 16); the caller writes the rest. Same products as the scalar loop.
// GCC 12's AVX-512 shuffle/unpack intrinsics start from an undefined register
// and trip -Wmaybe-uninitialized when inlined (a false positive).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
// Points (x, y, z, intensity) of 16 pixels to 4 cache lines at o (64-byte
// aligned), non-temporal.
__attribute__((target("avx512f"))) inline void streamPoints16(__m512 x, __m512 y, __m512 z,
                                                              __m512 i, float* o) {
  const __m512 xy_lo = _mm512_unpacklo_ps(x, y), xy_hi = _mm512_unpackhi_ps(x, y);
  const __m512 zi_lo = _mm512_unpacklo_ps(z, i), zi_hi = _mm512_unpackhi_ps(z, i);
  // Per 128-bit lane k: points 4k .. 4k+3 end up in p0..p3 (lane k).
  const __m512 p0 =
      _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(xy_lo), _mm512_castps_pd(zi_lo)));
  const __m512 p1 =
      _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(xy_lo), _mm512_castps_pd(zi_lo)));
  const __m512 p2 =
      _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(xy_hi), _mm512_castps_pd(zi_hi)));
  const __m512 p3 =
      _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(xy_hi), _mm512_castps_pd(zi_hi)));
  // 4 x 4 transpose of the 128-bit lanes: register k = points 4k .. 4k+3.
  const __m512 q0 = _mm512_shuffle_f32x4(p0, p1, _MM_SHUFFLE(1, 0, 1, 0));
  const __m512 q1 = _mm512_shuffle_f32x4(p2, p3, _MM_SHUFFLE(1, 0, 1, 0));
  const __m512 q2 = _mm512_shuffle_f32x4(p0, p1, _MM_SHUFFLE(3, 2, 3, 2));
  const __m512 q3 = _mm512_shuffle_f32x4(p2, p3, _MM_SHUFFLE(3, 2, 3, 2));
  _mm512_stream_ps(o, _mm512_shuffle_f32x4(q0, q1, _MM_SHUFFLE(2, 0, 2, 0)));
  _mm512_stream_ps(o + 16, _mm512_shuffle_f32x4(q0, q1, _MM_SHUFFLE(3, 1, 3, 1)));
  _mm512_stream_ps(o + 32, _mm512_shuffle_f32x4(q2, q3, _MM_SHUFFLE(2, 0, 2, 0)));
  _mm512_stream_ps(o + 48, _mm512_shuffle_f32x4(q2, q3, _MM_SHUFFLE(3, 1, 3, 1)));
}

__attribute__((target("avx512f"))) int streamPointsAvx512(int n, const float* z_row,
                                                          const float* rx, const float* ry,
                                                          const float* intensity,
                                                          PointXYZI* out) {
  int u = 0;
  for (; u + 16 <= n; u += 16) {
    const __m512 z = _mm512_loadu_ps(z_row + u);
    const __m512 x = _mm512_mul_ps(z, _mm512_loadu_ps(rx + u));
    const __m512 y = _mm512_mul_ps(z, _mm512_loadu_ps(ry + u));
    const __m512 i = intensity ? _mm512_loadu_ps(intensity + u) : _mm512_setzero_ps();
    streamPoints16(x, y, z, i, &out[u].x);
  }
  return u;
}

// Terms of the fused single-axis row: the ray's a = a0 x + a1 y + a2 and
// b = b0 x + b1 y + b2 (M3 and M1 or M2 of the axis), M[axis][3], M3[3] and
// the depth range.
struct AxisTerms {
  float a0, a1, a2, b0, b1, b2, m_axis, m3, min_z, max_z;
};

// The point of one pixel as the row functions compute it (the fused row's
// lead and tail; same operations as depthRow<0>, rowRays and the point
// loops, so the same bits).
inline PointXYZI fusedPoint(const AxisTerms& k, float p, float rx, float ry, float intensity) {
  const float ai = k.a0 * rx + k.a1 * ry + k.a2;
  const float b = k.b0 * rx + k.b1 * ry + k.b2;
  const float z = depthAlongRay(p, ai, b, k.m_axis, k.m3, k.min_z, k.max_z);
  return PointXYZI{z * rx, z * ry, z, intensity};
}

// A whole row with one map and no projector correction in one pass:
// rays (x0 + t (x1 - x0), or x0 itself without kInterpolate), depth and
// points, 16 pixels per iteration, none of the row buffers of the general
// path. Pixels [0, n) with `out` 64-byte aligned; returns the pixels written
// (a multiple of 16). Bit for bit the general path's results (test_triangulator).
template <bool kInterpolate>
__attribute__((target("avx512f"))) int fusedRowAvx512(int n, const AxisTerms& k, const float* p_row,
                                                      const float* x0, const float* x1,
                                                      const float* y0, const float* y1, float t,
                                                      const float* intensity, PointXYZI* out) {
  const __m512 a0 = _mm512_set1_ps(k.a0), a1 = _mm512_set1_ps(k.a1), a2 = _mm512_set1_ps(k.a2);
  const __m512 b0 = _mm512_set1_ps(k.b0), b1 = _mm512_set1_ps(k.b1), b2 = _mm512_set1_ps(k.b2);
  const __m512 m_axis = _mm512_set1_ps(k.m_axis), m3 = _mm512_set1_ps(k.m3);
  const __m512 min_z = _mm512_set1_ps(k.min_z), max_z = _mm512_set1_ps(k.max_z);
  const __m512 tiny = _mm512_set1_ps(1e-12f), nan = _mm512_set1_ps(kNaN);
  const __m512 tv = _mm512_set1_ps(t);
  int u = 0;
  for (; u + 16 <= n; u += 16) {
    __m512 rx = _mm512_loadu_ps(x0 + u), ry = _mm512_loadu_ps(y0 + u);
    if constexpr (kInterpolate) {
      rx = _mm512_add_ps(rx, _mm512_mul_ps(tv, _mm512_sub_ps(_mm512_loadu_ps(x1 + u), rx)));
      ry = _mm512_add_ps(ry, _mm512_mul_ps(tv, _mm512_sub_ps(_mm512_loadu_ps(y1 + u), ry)));
    }
    const __m512 p = _mm512_loadu_ps(p_row + u);
    const __m512 ai =
        _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(a0, rx), _mm512_mul_ps(a1, ry)), a2);
    const __m512 b = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(b0, rx), _mm512_mul_ps(b1, ry)), b2);
    const __m512 den = _mm512_sub_ps(_mm512_mul_ps(p, ai), b);
    const __m512 z_all = _mm512_div_ps(_mm512_sub_ps(m_axis, _mm512_mul_ps(p, m3)), den);
    const __mmask16 valid = _mm512_cmp_ps_mask(_mm512_abs_ps(den), tiny, _CMP_GT_OQ) &
                            _mm512_cmp_ps_mask(z_all, min_z, _CMP_GE_OQ) &
                            _mm512_cmp_ps_mask(z_all, max_z, _CMP_LE_OQ);
    const __m512 z = _mm512_mask_blend_ps(valid, nan, z_all);
    const __m512 i = intensity ? _mm512_loadu_ps(intensity + u) : _mm512_setzero_ps();
    streamPoints16(_mm512_mul_ps(z, rx), _mm512_mul_ps(z, ry), z, i, &out[u].x);
  }
  return u;
}
// Each statement below over the N vectors of 16 pixels in flight: one
// vector's correction is a long dependent chain (three divisions), so
// independent vectors are interleaved for the out-of-order core.
#define SL_LANES _Pragma("GCC unroll 8") for (int j = 0; j < N; ++j)

// c[0] x + c[1] y + c[2].
__attribute__((target("avx512f"))) inline __m512 linear16(const float* c, __m512 x, __m512 y) {
  return _mm512_add_ps(
      _mm512_add_ps(_mm512_mul_ps(_mm512_set1_ps(c[0]), x), _mm512_mul_ps(_mm512_set1_ps(c[1]), y)),
      _mm512_set1_ps(c[2]));
}

// epipolarDepth() of N x 16 pixels: the same operations in the same order.
// kK3: false when k3 = 0, then r2 (k1 + r2 k2) for r2 (k1 + r2 (k2 + r2 k3)),
// the same value for finite r2 (r2 0 = 0, k2 + 0 = k2).
template <int N, int kIterations, bool kK3>
__attribute__((target("avx512f"))) inline void epipolarDepthN(
    const EpipolarAxis& k, const __m512* x, const __m512* y, const __m512* ai,
    const __m512* q_along, const __m512* decoded, __m512 min_z, __m512 max_z, __m512* z) {
  const __m512 m_along = _mm512_set1_ps(k.m_along);
  const __m512 m3 = _mm512_set1_ps(k.m3);
  const __m512 c_along = _mm512_set1_ps(k.c_along), f_along = _mm512_set1_ps(k.f_along);
  const __m512 k1 = _mm512_set1_ps(k.k1), k2 = _mm512_set1_ps(k.k2), k3 = _mm512_set1_ps(k.k3);
  const __m512 two_t1 = _mm512_set1_ps(k.two_t1), t2 = _mm512_set1_ps(k.t2);
  const __m512 two = _mm512_set1_ps(2.0f);
  __m512 alpha[N], beta[N], target[N], a[N], a_prev[N], g_prev[N];
  SL_LANES {
    const __m512 la = linear16(k.la, x[j], y[j]);
    const __m512 lo = linear16(k.lo, x[j], y[j]);
    const __m512 lc = linear16(k.lc, x[j], y[j]);
    const __m512 inv = _mm512_div_ps(_mm512_set1_ps(-1.0f), lo);
    alpha[j] = _mm512_mul_ps(lc, inv);
    beta[j] = _mm512_mul_ps(la, inv);
    target[j] = _mm512_mul_ps(_mm512_sub_ps(decoded[j], c_along), _mm512_set1_ps(k.inv_f_along));
    a[j] = target[j];
  }
  for (int it = 0; it < kIterations; ++it) {
    SL_LANES {
      const __m512 o = _mm512_add_ps(alpha[j], _mm512_mul_ps(beta[j], a[j]));
      const __m512 aa = _mm512_mul_ps(a[j], a[j]);
      const __m512 r2 = _mm512_add_ps(aa, _mm512_mul_ps(o, o));
      const __m512 radial =
          kK3 ? _mm512_mul_ps(
                    r2,
                    _mm512_add_ps(k1, _mm512_mul_ps(r2, _mm512_add_ps(k2, _mm512_mul_ps(r2, k3)))))
              : _mm512_mul_ps(r2, _mm512_add_ps(k1, _mm512_mul_ps(r2, k2)));
      const __m512 shift = _mm512_add_ps(
          _mm512_add_ps(_mm512_mul_ps(a[j], radial), _mm512_mul_ps(two_t1, _mm512_mul_ps(a[j], o))),
          _mm512_mul_ps(t2, _mm512_add_ps(r2, _mm512_mul_ps(two, aa))));
      const __m512 g = it == 0 ? shift : _mm512_add_ps(_mm512_sub_ps(a[j], target[j]), shift);
      __m512 step = g;
      if (it > 0) {
        const __m512 dg = _mm512_sub_ps(g, g_prev[j]), da = _mm512_sub_ps(a[j], a_prev[j]);
        const __mmask16 sane =
            _mm512_cmp_ps_mask(_mm512_abs_ps(_mm512_sub_ps(dg, da)),
                               _mm512_mul_ps(_mm512_set1_ps(0.5f), _mm512_abs_ps(da)), _CMP_LT_OQ);
        step = _mm512_mask_div_ps(g, sane, _mm512_mul_ps(g, da), dg);
      }
      a_prev[j] = a[j];
      g_prev[j] = g;
      a[j] = _mm512_sub_ps(a[j], step);
    }
  }
  SL_LANES {
    const __m512 p = _mm512_add_ps(_mm512_mul_ps(f_along, a[j]), c_along);
    // depthAlongRay().
    const __m512 den = _mm512_sub_ps(_mm512_mul_ps(p, ai[j]), q_along[j]);
    const __m512 z_all = _mm512_div_ps(_mm512_sub_ps(m_along, _mm512_mul_ps(p, m3)), den);
    const __mmask16 valid =
        _mm512_cmp_ps_mask(_mm512_abs_ps(den), _mm512_set1_ps(1e-12f), _CMP_GT_OQ) &
        _mm512_cmp_ps_mask(z_all, min_z, _CMP_GE_OQ) & _mm512_cmp_ps_mask(z_all, max_z, _CMP_LE_OQ);
    z[j] = _mm512_mask_blend_ps(valid, _mm512_set1_ps(kNaN), z_all);
  }
}

// fusedRowAvx512() with the epipolar projector correction (kIterations
// iterations), N vectors of 16 pixels at a time, then single vectors:
// bit for bit the general path's results (test_triangulator).
template <int N, bool kInterpolate, int kIterations, bool kK3>
__attribute__((target("avx512f"))) int fusedEpipolarRowAvx512(
    int n, const AxisTerms& k, const EpipolarAxis& e, const float* p_row, const float* x0,
    const float* x1, const float* y0, const float* y1, float t, const float* intensity,
    PointXYZI* out) {
  const __m512 a0 = _mm512_set1_ps(k.a0), a1 = _mm512_set1_ps(k.a1), a2 = _mm512_set1_ps(k.a2);
  const __m512 b0 = _mm512_set1_ps(k.b0), b1 = _mm512_set1_ps(k.b1), b2 = _mm512_set1_ps(k.b2);
  const __m512 min_z = _mm512_set1_ps(k.min_z), max_z = _mm512_set1_ps(k.max_z);
  const __m512 tv = _mm512_set1_ps(t);
  int u = 0;
  for (; u + 16 * N <= n; u += 16 * N) {
    __m512 rx[N], ry[N], ai[N], b[N], p[N], z[N];
    SL_LANES {
      const int v = u + 16 * j;
      rx[j] = _mm512_loadu_ps(x0 + v);
      ry[j] = _mm512_loadu_ps(y0 + v);
      if constexpr (kInterpolate) {
        rx[j] =
            _mm512_add_ps(rx[j], _mm512_mul_ps(tv, _mm512_sub_ps(_mm512_loadu_ps(x1 + v), rx[j])));
        ry[j] =
            _mm512_add_ps(ry[j], _mm512_mul_ps(tv, _mm512_sub_ps(_mm512_loadu_ps(y1 + v), ry[j])));
      }
      ai[j] = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(a0, rx[j]), _mm512_mul_ps(a1, ry[j])), a2);
      b[j] = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(b0, rx[j]), _mm512_mul_ps(b1, ry[j])), b2);
      p[j] = _mm512_loadu_ps(p_row + v);
    }
    epipolarDepthN<N, kIterations, kK3>(e, rx, ry, ai, b, p, min_z, max_z, z);
    SL_LANES {
      const int v = u + 16 * j;
      const __m512 i = intensity ? _mm512_loadu_ps(intensity + v) : _mm512_setzero_ps();
      streamPoints16(_mm512_mul_ps(z[j], rx[j]), _mm512_mul_ps(z[j], ry[j]), z[j], i, &out[v].x);
    }
  }
  if constexpr (N > 1) {
    u += fusedEpipolarRowAvx512<1, kInterpolate, kIterations, kK3>(
        n - u, k, e, p_row + u, x0 + u, x1 + u, y0 + u, y1 + u, t,
        intensity ? intensity + u : nullptr, out + u);
  }
  return u;
}
#undef SL_LANES
#pragma GCC diagnostic pop

bool cpuHasAvx512() { return __builtin_cpu_supports("avx512f"); }

// Vectors of 16 pixels in flight in the corrected fused row.
constexpr int kEpipolarLanes = SL_EPIPOLAR_LANES;
#else
bool cpuHasAvx512() { return false; }
#endif

}  // namespace

struct Triangulator::Impl {
  int width = 0;
  int height = 0;
  TriangulatorOptions options;
  bool avx512_points = cpuHasAvx512();
  Axis preferred = kColumn;  // for Use::kBest

  // Per camera pixel: the undistorted normalized ray r = (rx, ry, 1) in the
  // camera frame. With M = K_p [R | t] in projector px, the terms
  // a = M3[0:3].r and b[axis] = M1[0:3].r (columns) or M2[0:3].r (rows) are
  // formed per row from the ray (two multiply-adds each: cheaper than
  // reading them from memory).
  //
  // The rays are read from a grid of nodes every ray_step pixels,
  // interpolated bilinearly, when that is within kMaxRayError of the exact
  // ray at every pixel (checked by the constructor; the ray varies smoothly
  // with the lens distortion); otherwise (ray_step 0) from per-pixel arrays.
  // The grid is kept as its rows (every ray_step-th camera row) already
  // interpolated along u, so a camera row costs one interpolation between
  // two of them per pixel. It replaces 8 bytes per pixel of memory reads per
  // scan (1440 x 1080: 12 MB) with 1/ray_step of that, which stays in cache.
  static constexpr double kMaxRayError = 2e-7;  // 0.1 um across the ray at 500 mm
  int ray_step = 0;                             // 16, 8 or 4; 0: per-pixel arrays
  std::vector<float> grid_x, grid_y;            // grid rows x width; ray_step 0: all rows

  // Where the rays of camera row v come from: x0 + t (x1 - x0) between two
  // grid rows, or x0 itself (the per-pixel arrays, interpolate false).
  struct RaySource {
    const float *x0, *x1, *y0, *y1;
    float t;
    bool interpolate;
  };
  RaySource raySource(int v) const;
  // The rays of camera row v: pointers into the arrays (ray_step 0), or
  // rx_row, ry_row (width floats each) filled from the grid.
  std::pair<const float*, const float*> rowRays(int v, float* rx_row, float* ry_row) const;
  // Chooses ray_step and fills the grid (or the per-pixel arrays).
  void buildRays(const PinholeModel& cam);
  // Floats of row scratch rowRays() needs.
  int rayScratch() const { return ray_step == 0 ? 0 : 2 * width; }
  float m_rows[3][3] = {};  // M[0:3][0:3]
  double m_full[3][3] = {};  // the same in double
  double m_t[2] = {0, 0};   // M1[3], M2[3]
  double m3_t = 0;          // M3[3] = t.z (mm)

  // Projector model for the distortion correction.
  bool correct_projector = false;
  double proj_f[2] = {0, 0}, inv_proj_f[2] = {0, 0}, proj_c[2] = {0, 0};
  double proj_dist[5] = {0, 0, 0, 0, 0};

  // The along-ray projector distortion correction (ProjectorCorrection::
  // kAlongRay, the reference) for one row of pixels, in place on p (decoded,
  // distorted projector px -> undistorted projector px).
  //
  // For pixel i and coordinate p along `axis`, with n = M[axis][3] - p M3[3]
  // and d = p a - b[axis], the depth is z = n / d, and
  // M (z r; 1) * d = (n b_col + M1[3] d, n b_row + M2[3] d, n a + M3[3] d)
  // gives the undistorted projector pixel of the point without forming it, at
  // the cost of one division.
  //
  // The correction solves g(p) = p + delta(X(p)) - decoded = 0 for the
  // undistorted coordinate p, where delta is the projector distortion
  // (distorted minus undistorted projection) at the point triangulated from
  // p. The first step is the plain shift p = decoded - delta; later steps are
  // secant steps on g, which cost the same one evaluation of delta but remove
  // the linear part of delta's variation along the ray (measured: 2 steps
  // leave < 1e-3 mm where plain shifting leaves ~1e-2 mm). A pixel whose
  // point is not in front of both devices, or NaN, keeps its p.
  //
  // Single precision (the maps and the cloud are float; the triangulator
  // tests bound the error), branch-free over the row so that it vectorizes
  // (needs -fno-trapping-math, set for this file in CMakeLists.txt).
  // is_column: 1 where the pixel's coordinate is a column, else 0.
  // Constants of the correction in single precision.
  struct Correction {
    float m_col, m_row, m3, cx, cy, ifx, ify, fx, fy, k1, k2, p1, p2, k3;
  };
  Correction correction() const {
    return Correction{float(m_t[kColumn]),  float(m_t[kRow]),    float(m3_t),
                      float(proj_c[0]),     float(proj_c[1]),    float(inv_proj_f[0]),
                      float(inv_proj_f[1]), float(proj_f[0]),    float(proj_f[1]),
                      float(proj_dist[0]),  float(proj_dist[1]), float(proj_dist[2]),
                      float(proj_dist[3]),  float(proj_dist[4])};
  }

  // One correction step for one pixel (col: 1 column, 0 row; a, b_col, b_row
  // its terms; decoded its coordinate), updating p and the secant state.
  // Branch-free so that the row loops calling it vectorize.
  // kAxis: kColumn or kRow when every pixel of the row uses that axis (the
  // other axis' terms then fold away), kMixedAxes to read col_flag.
  template <bool kSecant, int kAxis = 2>
  static void correctionStep(const Correction& k, float col_flag, float ai, float bc, float br,
                             float decoded, float& p, float& p_prev, float& g_prev) {
    const bool col = kAxis == 2 ? col_flag != 0.0f : kAxis == kColumn;
    const float pi = p;
    const float n = (col ? k.m_col : k.m_row) - pi * k.m3;
    const float d = pi * ai - (col ? bc : br);
    const float w = n * ai + k.m3 * d;  // projector-frame depth times d
    const bool in_front = (n * d > 0.0f) & (w * d > 0.0f);
    const float inv_w = 1.0f / w;
    const float xn = ((n * bc + k.m_col * d) * inv_w - k.cx) * k.ifx;
    const float yn = ((n * br + k.m_row * d) * inv_w - k.cy) * k.ify;
    // Brown-Conrady, as PinholeModel::normalizedToPixel; the shift only.
    const float r2 = xn * xn + yn * yn;
    const float radial = r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
    const float dx = xn * radial + 2.0f * k.p1 * xn * yn + k.p2 * (r2 + 2.0f * xn * xn);
    const float dy = yn * radial + k.p1 * (r2 + 2.0f * yn * yn) + 2.0f * k.p2 * xn * yn;
    const float shift = col ? k.fx * dx : k.fy * dy;
    const float g = pi + shift - decoded;
    float delta_p = g;  // plain shift: slope 1
    if constexpr (kSecant) {
      const float dg = g - g_prev, dp = pi - p_prev;
      // Secant slope dg / dp, used only where it is sane (0.5 .. 2).
      const bool sane = (dg * dp > 0.0f) & (std::abs(dg) > 0.5f * std::abs(dp)) &
                        (std::abs(dg) < 2.0f * std::abs(dp));
      delta_p = sane ? g * dp / dg : g;
    }
    p_prev = pi;
    g_prev = g;
    p = in_front ? pi - delta_p : pi;
  }

  // Constants of the epipolar correction for pixels decoded along `axis`.
  EpipolarAxis epipolarAxis(int axis) const;

  // Depth of one row into z_row with the epipolar correction:
  // options.projector_distortion_iterations iterations (kIterations 1 or 2,
  // or -1 for any count, a loop that does not vectorize). kAxis: kColumn or
  // kRow when every pixel of the row uses that axis (no second map), 2 to
  // pick per pixel as depthRow() does.
  template <int kIterations, int kAxis>
  SL_MULTIVERSION void epipolarDepthRow(const float* first_row, const float* second_row,
                                        float first_is_column, float second_is_column,
                                        const float* rx, const float* ry, float* z_row) const;

  // Rows [map_begin, map_end) of the maps into cloud rows from cloud_begin.
  void triangulate(const ProjectorMaps& maps, int first, int second, int map_begin, int map_end,
                   int cloud_begin, PointCloud& cloud) const;
  // Depth of one row into z_row (NaN where invalid); kIterations >= 0 fuses
  // selection, terms, that many correction steps and the depth into one
  // loop; -1 runs options.projector_distortion_iterations as row passes
  // (scratch: 8 rows of width floats).
  template <int kIterations>
  SL_MULTIVERSION void depthRow(const float* first_row, const float* second_row,
                                float first_is_column, float second_is_column, const float* rx,
                                const float* ry, float* scratch, float* z_row) const;
};

Triangulator::Triangulator(const CameraProjectorCalibration& calibration,
                           TriangulatorOptions options) {
  const PinholeModel& cam = calibration.camera;
  const PinholeModel& proj = calibration.projector;
  if (cam.width <= 0 || cam.height <= 0) {
    throw std::invalid_argument("Triangulator: camera size must be positive");
  }
  if (!(cam.fx > 0 && cam.fy > 0 && proj.fx > 0 && proj.fy > 0)) {
    throw std::invalid_argument("Triangulator: focal lengths must be positive");
  }
  if (!(options.min_depth_mm > 0 && options.min_depth_mm < options.max_depth_mm)) {
    throw std::invalid_argument("Triangulator: need 0 < min_depth_mm < max_depth_mm");
  }
  if (options.projector_distortion_iterations < 0) {
    throw std::invalid_argument("Triangulator: projector_distortion_iterations must be >= 0");
  }

  auto impl = std::make_shared<Impl>();
  impl->width = cam.width;
  impl->height = cam.height;
  impl->options = options;
  const Eigen::Vector3d& t = calibration.t;
  impl->preferred = std::abs(t.x()) >= std::abs(t.y()) ? kColumn : kRow;

  Eigen::Matrix<double, 3, 4> rt;
  rt.leftCols<3>() = calibration.R;
  rt.col(3) = t;
  const Eigen::Matrix<double, 3, 4> m = proj.K() * rt;
  impl->m_t[kColumn] = m(0, 3);
  impl->m_t[kRow] = m(1, 3);
  impl->m3_t = m(2, 3);

  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      impl->m_rows[r][c] = static_cast<float>(m(r, c));
      impl->m_full[r][c] = m(r, c);
    }
  impl->buildRays(cam);

  impl->correct_projector = proj.hasDistortion() && options.projector_distortion_iterations > 0;
  impl->proj_f[0] = proj.fx;
  impl->proj_f[1] = proj.fy;
  impl->inv_proj_f[0] = 1.0 / proj.fx;
  impl->inv_proj_f[1] = 1.0 / proj.fy;
  impl->proj_c[0] = proj.cx;
  impl->proj_c[1] = proj.cy;
  for (int k = 0; k < 5; ++k) impl->proj_dist[k] = proj.distortion[k];
  impl_ = std::move(impl);
}

std::pair<int, int> Triangulator::axesFor(const ProjectorMaps& maps, int band_rows) const {
  const Impl& im = *impl_;
  const cv::Size size(im.width, im.height);
  auto check = [&](const cv::Mat& map, const char* name) {
    if (map.empty()) return;
    const bool size_ok =
        band_rows < 0 ? map.size() == size : map.cols == im.width && map.rows >= band_rows;
    if (band_rows >= 0 && map.type() == CV_32FC1 && !size_ok) {
      throw std::invalid_argument(std::string("Triangulator: band.") + name + " must be " +
                                  std::to_string(im.width) + " wide with at least " +
                                  std::to_string(band_rows) + " rows");
    }
    if (map.type() != CV_32FC1 || !size_ok) {
      throw std::invalid_argument(std::string("Triangulator: maps.") + name +
                                  " must be CV_32FC1 of the camera size " +
                                  std::to_string(im.width) + "x" + std::to_string(im.height));
    }
  };
  check(maps.up, "up");
  check(maps.vp, "vp");
  check(maps.offset, "offset");

  const bool have[2] = {!maps.up.empty(), !maps.vp.empty()};
  using Use = TriangulatorOptions::Use;
  // first / second: the axes tried per pixel, in order (-1 = none).
  int first = -1, second = -1;
  switch (im.options.use) {
    case Use::kColumns:
      if (!have[kColumn]) throw std::invalid_argument("Triangulator: Use::kColumns needs maps.up");
      first = kColumn;
      break;
    case Use::kRows:
      if (!have[kRow]) throw std::invalid_argument("Triangulator: Use::kRows needs maps.vp");
      first = kRow;
      break;
    case Use::kBest: {
      const int other = 1 - im.preferred;
      if (have[im.preferred]) first = im.preferred;
      if (have[other]) (first < 0 ? first : second) = other;
      if (first < 0) throw std::invalid_argument("Triangulator: maps have neither up nor vp");
      break;
    }
  }
  return {first, second};
}

void Triangulator::prepare(const ProjectorMaps& maps, PointCloud& cloud) const {
  axesFor(maps);
  prepareCloud(maps.camera_id, maps.stamp_ns, cloud);
}

PointCloud Triangulator::triangulate(const ProjectorMaps& maps) const {
  PointCloud cloud;
  prepare(maps, cloud);
  triangulateRows(maps, 0, impl_->height, cloud);
  return cloud;
}

void Triangulator::triangulateRows(const ProjectorMaps& maps, int row_begin, int row_end,
                                   PointCloud& cloud) const {
  const auto [first, second] = axesFor(maps);
  impl_->triangulate(maps, first, second, row_begin, row_end, row_begin, cloud);
}

void Triangulator::triangulateBand(const ProjectorMaps& band, int row_begin, int row_end,
                                   PointCloud& cloud) const {
  const Impl& im = *impl_;
  if (row_begin < 0 || row_end > im.height || row_begin > row_end)
    throw std::invalid_argument("Triangulator: band rows outside the camera image");
  if (cloud.width != im.width || cloud.height != im.height ||
      cloud.points.size() != static_cast<std::size_t>(im.width) * im.height)
    throw std::invalid_argument("Triangulator: cloud not prepared (prepareCloud())");
  const auto [first, second] = axesFor(band, row_end - row_begin);
  im.triangulate(band, first, second, 0, row_end - row_begin, row_begin, cloud);
}

const TriangulatorOptions& Triangulator::options() const { return impl_->options; }

int Triangulator::rayGridStep() const { return impl_->ray_step; }

void Triangulator::prepareCloud(const std::string& frame_id, TimestampNs stamp_ns,
                                PointCloud& cloud) const {
  cloud.frame_id = frame_id;
  cloud.stamp_ns = stamp_ns;
  cloud.width = impl_->width;
  cloud.height = impl_->height;
  cloud.points.resize(static_cast<std::size_t>(impl_->width) * impl_->height);
}

Triangulator::Impl::RaySource Triangulator::Impl::raySource(int v) const {
  const bool interpolate = ray_step != 0;
  const std::size_t start = static_cast<std::size_t>(interpolate ? v / ray_step : v) * width;
  const float* x0 = grid_x.data() + start;
  const float* y0 = grid_y.data() + start;
  if (!interpolate) return RaySource{x0, x0, y0, y0, 0.0f, false};
  // Between grid rows j and j + 1 (t exact in float: ray_step is a power of 2).
  const float t = static_cast<float>(v % ray_step) / static_cast<float>(ray_step);
  return RaySource{x0, x0 + width, y0, y0 + width, t, true};
}

std::pair<const float*, const float*> Triangulator::Impl::rowRays(int v, float* __restrict rx_row,
                                                                  float* __restrict ry_row) const {
  const RaySource r = raySource(v);
  if (!r.interpolate) return {r.x0, r.y0};
  const float* __restrict x0 = r.x0;
  const float* __restrict y0 = r.y0;
  const float* __restrict x1 = r.x1;
  const float* __restrict y1 = r.y1;
  const float t = r.t;
  for (int u = 0; u < width; ++u) {
    rx_row[u] = x0[u] + t * (x1[u] - x0[u]);
    ry_row[u] = y0[u] + t * (y1[u] - y0[u]);
  }
  return {rx_row, ry_row};
}

void Triangulator::Impl::buildRays(const PinholeModel& cam) {
  const std::size_t n = static_cast<std::size_t>(width) * height;
  std::vector<double> exact_x(n), exact_y(n);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector2d xn = cam.pixelToNormalized({double(u), double(v)});
      exact_x[static_cast<std::size_t>(v) * width + u] = xn.x();
      exact_y[static_cast<std::size_t>(v) * width + u] = xn.y();
    }
  }
  std::vector<float> row_x(width), row_y(width);
  for (const int step : {16, 8, 4}) {
    // Nodes at multiples of step, up to the first beyond the last pixel (the
    // interpolation reads node k + 1 even where its weight is 0); each grid
    // row interpolated along u between its nodes.
    ray_step = step;
    const int grid_cols = (width - 1) / step + 2;
    const int grid_rows = (height - 1) / step + 2;
    grid_x.assign(static_cast<std::size_t>(grid_rows) * width, 0.0f);
    grid_y.assign(grid_x.size(), 0.0f);
    std::vector<float> node_x(grid_cols), node_y(grid_cols);
    for (int j = 0; j < grid_rows; ++j) {
      for (int k = 0; k < grid_cols; ++k) {
        const Eigen::Vector2d xn = cam.pixelToNormalized({double(k * step), double(j * step)});
        node_x[k] = static_cast<float>(xn.x());
        node_y[k] = static_cast<float>(xn.y());
      }
      float* gx = grid_x.data() + static_cast<std::size_t>(j) * width;
      float* gy = grid_y.data() + static_cast<std::size_t>(j) * width;
      for (int u = 0; u < width; ++u) {
        const int k = u / step;
        const float w = static_cast<float>(u % step) / static_cast<float>(step);
        gx[u] = node_x[k] + w * (node_x[k + 1] - node_x[k]);
        gy[u] = node_y[k] + w * (node_y[k + 1] - node_y[k]);
      }
    }
    // The check runs the interpolation the triangulation runs.
    double worst = 0.0;
    for (int v = 0; v < height && worst <= kMaxRayError; ++v) {
      const auto [x, y] = rowRays(v, row_x.data(), row_y.data());
      const std::size_t start = static_cast<std::size_t>(v) * width;
      for (int u = 0; u < width; ++u) {
        worst = std::max(
            {worst, std::abs(x[u] - exact_x[start + u]), std::abs(y[u] - exact_y[start + u])});
      }
    }
    if (worst <= kMaxRayError) return;
  }
  ray_step = 0;
  grid_x.assign(exact_x.begin(), exact_x.end());
  grid_y.assign(exact_y.begin(), exact_y.end());
}

template <int kIterations>
void Triangulator::Impl::depthRow(const float* __restrict first_row,
                                  const float* __restrict second_row, float first_is_column,
                                  float second_is_column, const float* __restrict rx,
                                  const float* __restrict ry, float* __restrict scratch,
                                  float* __restrict z_row) const {
  const Correction k = correction();
  const float min_z = options.min_depth_mm;
  const float max_z = options.max_depth_mm;
  const float a0 = m_rows[2][0], a1 = m_rows[2][1], a2 = m_rows[2][2];
  const float bc0 = m_rows[0][0], bc1 = m_rows[0][1], bc2 = m_rows[0][2];
  const float br0 = m_rows[1][0], br1 = m_rows[1][1], br2 = m_rows[1][2];
  // f - f is 0 for finite f, NaN for NaN or +-inf: then the second map.
  auto select = [&](int u, float& decoded, float& col) {
    const float f = first_row[u], s = second_row[u];
    const float use_first = (f - f) == 0.0f ? 1.0f : 0.0f;
    decoded = use_first != 0.0f ? f : s;
    col = second_is_column + use_first * (first_is_column - second_is_column);
  };
  auto depth = [&](float col_flag, float ai, float bc, float br, float p) {
    const bool col = col_flag != 0.0f;
    return depthAlongRay(p, ai, col ? bc : br, col ? k.m_col : k.m_row, k.m3, min_z, max_z);
  };
  if constexpr (kIterations >= 0) {
    SL_ROW_LOOP
    for (int u = 0; u < width; ++u) {
      float decoded, col;
      select(u, decoded, col);
      const float x = rx[u], y = ry[u];
      const float ai = a0 * x + a1 * y + a2;
      const float bc = bc0 * x + bc1 * y + bc2;
      const float br = br0 * x + br1 * y + br2;
      float p = decoded, p_prev = 0.0f, g_prev = 0.0f;
      if constexpr (kIterations >= 1)
        correctionStep<false>(k, col, ai, bc, br, decoded, p, p_prev, g_prev);
      if constexpr (kIterations >= 2)
        correctionStep<true>(k, col, ai, bc, br, decoded, p, p_prev, g_prev);
      static_assert(kIterations <= 2, "fused loop for up to 2 iterations");
      z_row[u] = depth(col, ai, bc, br, p);
    }
  } else {
    float* __restrict decoded = scratch;
    float* __restrict p = decoded + width;
    float* __restrict is_column = p + width;
    float* __restrict p_prev = is_column + width;
    float* __restrict g_prev = p_prev + width;
    float* __restrict a_row = g_prev + width;
    float* __restrict b_col_row = a_row + width;
    float* __restrict b_row_row = b_col_row + width;
    SL_ROW_LOOP
    for (int u = 0; u < width; ++u) {
      select(u, decoded[u], is_column[u]);
      p[u] = decoded[u];
      const float x = rx[u], y = ry[u];
      a_row[u] = a0 * x + a1 * y + a2;
      b_col_row[u] = bc0 * x + bc1 * y + bc2;
      b_row_row[u] = br0 * x + br1 * y + br2;
    }
    // Pixels with a finite coordinate on the second axis (NaN pixels stay NaN
    // whatever their axis). An integer OR: a float sum may not be reordered,
    // so it would be added up one lane at a time (docs/measurements.md).
    unsigned on_second = 0;
    SL_ROW_LOOP
    for (int u = 0; u < width; ++u)
      on_second |= static_cast<unsigned>((is_column[u] != first_is_column) &
                                         ((decoded[u] - decoded[u]) == 0.0f));
    auto passes = [&]<int kAxis>() {
      for (int it = 0; it < options.projector_distortion_iterations; ++it) {
        if (it == 0) {
          SL_ROW_LOOP
          for (int u = 0; u < width; ++u)
            correctionStep<false, kAxis>(k, is_column[u], a_row[u], b_col_row[u], b_row_row[u],
                                         decoded[u], p[u], p_prev[u], g_prev[u]);
        } else {
          SL_ROW_LOOP
          for (int u = 0; u < width; ++u)
            correctionStep<true, kAxis>(k, is_column[u], a_row[u], b_col_row[u], b_row_row[u],
                                        decoded[u], p[u], p_prev[u], g_prev[u]);
        }
      }
    };
    if (on_second != 0) {
      passes.template operator()<2>();
    } else if (first_is_column != 0.0f) {
      passes.template operator()<kColumn>();
    } else {
      passes.template operator()<kRow>();
    }
    SL_ROW_LOOP
    for (int u = 0; u < width; ++u)
      z_row[u] = depth(is_column[u], a_row[u], b_col_row[u], b_row_row[u], p[u]);
  }
}

EpipolarAxis Triangulator::Impl::epipolarAxis(int axis) const {
  const int other = 1 - axis;
  // Rows of M (double) and the line's coefficients on r in (along, other, 1)
  // projector px: l_along = M[other][3] M3 - M3[3] M[other], l_other =
  // M3[3] M[along] - M[along][3] M3, l_const = M[along][3] M[other] -
  // M[other][3] M[along]; in normalized coordinates (a = (u - c) / f)
  // la = f_along l_along, lo = f_other l_other, lc = c_along l_along +
  // c_other l_other + l_const.
  EpipolarAxis k{};
  for (int i = 0; i < 3; ++i) {
    const double along = m_full[axis][i], across = m_full[other][i], third = m_full[2][i];
    const double l_along = m_t[other] * third - m3_t * across;
    const double l_other = m3_t * along - m_t[axis] * third;
    const double l_const = m_t[axis] * across - m_t[other] * along;
    k.la[i] = float(proj_f[axis] * l_along);
    k.lo[i] = float(proj_f[other] * l_other);
    k.lc[i] = float(proj_c[axis] * l_along + proj_c[other] * l_other + l_const);
  }
  const bool col = axis == kColumn;
  k.m_along = float(m_t[axis]);
  k.m3 = float(m3_t);
  k.f_along = float(proj_f[axis]);
  k.c_along = float(proj_c[axis]);
  k.inv_f_along = float(inv_proj_f[axis]);
  k.k1 = float(proj_dist[0]);
  k.k2 = float(proj_dist[1]);
  k.k3 = float(proj_dist[4]);
  k.two_k2 = float(2.0 * proj_dist[1]);
  k.three_k3 = float(3.0 * proj_dist[4]);
  k.two_t1 = float(2.0 * proj_dist[col ? 2 : 3]);
  k.t2 = float(proj_dist[col ? 3 : 2]);
  return k;
}

template <int kIterations, int kAxis>
void Triangulator::Impl::epipolarDepthRow(const float* __restrict first_row,
                                          const float* __restrict second_row, float first_is_column,
                                          float second_is_column, const float* __restrict rx,
                                          const float* __restrict ry,
                                          float* __restrict z_row) const {
  const EpipolarAxis kc = epipolarAxis(kColumn), kr = epipolarAxis(kRow);
  const int iterations = options.projector_distortion_iterations;
  const float min_z = options.min_depth_mm;
  const float max_z = options.max_depth_mm;
  const float a0 = m_rows[2][0], a1 = m_rows[2][1], a2 = m_rows[2][2];
  const float bc0 = m_rows[0][0], bc1 = m_rows[0][1], bc2 = m_rows[0][2];
  const float br0 = m_rows[1][0], br1 = m_rows[1][1], br2 = m_rows[1][2];
  SL_ROW_LOOP
  for (int u = 0; u < width; ++u) {
    // As depthRow(): the first map where finite, else the second.
    const float f = first_row[u], s = second_row[u];
    const float use_first = (f - f) == 0.0f ? 1.0f : 0.0f;
    const float decoded = use_first != 0.0f ? f : s;
    const float col_flag = second_is_column + use_first * (first_is_column - second_is_column);
    const bool col = kAxis == 2 ? col_flag != 0.0f : kAxis == kColumn;
    const float x = rx[u], y = ry[u];
    const float ai = a0 * x + a1 * y + a2;
    const float bc = bc0 * x + bc1 * y + bc2;
    const float br = br0 * x + br1 * y + br2;
    EpipolarAxis k;
    if constexpr (kAxis == 2) {
      // Field by field, so that the loop vectorizes with blends.
      k.m_along = col ? kc.m_along : kr.m_along;
      k.m3 = kc.m3;
      for (int i = 0; i < 3; ++i) {
        k.la[i] = col ? kc.la[i] : kr.la[i];
        k.lo[i] = col ? kc.lo[i] : kr.lo[i];
        k.lc[i] = col ? kc.lc[i] : kr.lc[i];
      }
      k.f_along = col ? kc.f_along : kr.f_along;
      k.c_along = col ? kc.c_along : kr.c_along;
      k.inv_f_along = col ? kc.inv_f_along : kr.inv_f_along;
      k.k1 = kc.k1;
      k.k2 = kc.k2;
      k.k3 = kc.k3;
      k.two_k2 = kc.two_k2;
      k.three_k3 = kc.three_k3;
      k.two_t1 = col ? kc.two_t1 : kr.two_t1;
      k.t2 = col ? kc.t2 : kr.t2;
    } else {
      k = kAxis == kColumn ? kc : kr;
    }
    z_row[u] =
        epipolarDepth<kIterations>(k, x, y, ai, col ? bc : br, decoded, iterations, min_z, max_z);
  }
}

void Triangulator::Impl::triangulate(const ProjectorMaps& maps, int first, int second,
                                     int map_begin, int map_end, int cloud_begin,
                                     PointCloud& cloud) const {
  const cv::Mat* coord_maps[2] = {&maps.up, &maps.vp};
  const int iterations = correct_projector ? options.projector_distortion_iterations : 0;
  const bool epipolar =
      options.projector_correction == TriangulatorOptions::ProjectorCorrection::kEpipolar;
  // Row scratch: the depth row, the pass-wise correction's state, the rays.
  const std::size_t depth_floats =
      (iterations > 0 && !epipolar ? 9 : 1) * static_cast<std::size_t>(width);
  const auto scratch = std::make_unique_for_overwrite<float[]>(depth_floats + rayScratch());
  float* z_row = scratch.get();
  float* rx_row = z_row + depth_floats;
  float* ry_row = rx_row + width;
  const float first_is_column = first == kColumn ? 1.0f : 0.0f;
  const float second_is_column = second == kColumn ? 1.0f : 0.0f;
#if defined(SL_HAVE_AVX512_POINTS)
  // One map, no projector correction or the epipolar one with up to 2
  // iterations (the common cases): the fused row.
  const bool fused =
      avx512_points && second < 0 && (iterations == 0 || (epipolar && iterations <= 2));
  const AxisTerms terms{m_rows[2][0],        m_rows[2][1],     m_rows[2][2],
                        m_rows[first][0],    m_rows[first][1], m_rows[first][2],
                        float(m_t[first]),   float(m3_t),      options.min_depth_mm,
                        options.max_depth_mm};
  const EpipolarAxis epipolar_terms = epipolarAxis(first);
#endif
  for (int row = map_begin; row < map_end; ++row) {
    const int v = row - map_begin + cloud_begin;
    const float* first_row = coord_maps[first]->ptr<float>(row);
    // Without a second map the first one stands in (its NaNs stay NaN).
    const float* second_row = second >= 0 ? coord_maps[second]->ptr<float>(row) : first_row;
    const float* __restrict offset_row =
        maps.offset.empty() ? nullptr : maps.offset.ptr<float>(row);
    const std::size_t row_start = static_cast<std::size_t>(v) * width;
#if defined(SL_HAVE_AVX512_POINTS)
    const std::uintptr_t misalignment =
        reinterpret_cast<std::uintptr_t>(cloud.points.data() + row_start) & 63;
    if (fused && (misalignment & 15) == 0) {
      // The rays as rowRays() forms them.
      const RaySource r = raySource(v);
      PointXYZI* out = cloud.points.data() + row_start;
      auto scalar = [&](int u) {
        const float rx = r.interpolate ? r.x0[u] + r.t * (r.x1[u] - r.x0[u]) : r.x0[u];
        const float ry = r.interpolate ? r.y0[u] + r.t * (r.y1[u] - r.y0[u]) : r.y0[u];
        const float intensity = offset_row ? offset_row[u] : 0.0f;
        if (iterations == 0) {
          out[u] = fusedPoint(terms, first_row[u], rx, ry, intensity);
          return;
        }
        const float ai = terms.a0 * rx + terms.a1 * ry + terms.a2;
        const float b = terms.b0 * rx + terms.b1 * ry + terms.b2;
        const float z = epipolarDepth<-1>(epipolar_terms, rx, ry, ai, b, first_row[u], iterations,
                                          terms.min_z, terms.max_z);
        out[u] = PointXYZI{z * rx, z * ry, z, intensity};
      };
      // Up to 3 points to reach a cache-line boundary, whole lines, the rest.
      const int lead = std::min(width, static_cast<int>(((64 - misalignment) & 63) / 16));
      int u = 0;
      for (; u < lead; ++u) scalar(u);
      const float* intensity = offset_row ? offset_row + u : nullptr;
      const int n = width - u;
      const float *p = first_row + u, *x0 = r.x0 + u, *x1 = r.x1 + u, *y0 = r.y0 + u,
                  *y1 = r.y1 + u;
      PointXYZI* o = out + u;
      if (iterations == 0) {
        u += r.interpolate ? fusedRowAvx512<true>(n, terms, p, x0, x1, y0, y1, r.t, intensity, o)
                           : fusedRowAvx512<false>(n, terms, p, x0, x1, y0, y1, r.t, intensity, o);
      } else {
        auto row = [&]<bool kInterpolate, int kIterations>() {
          return epipolar_terms.k3 != 0.0f
                     ? fusedEpipolarRowAvx512<kEpipolarLanes, kInterpolate, kIterations, true>(
                           n, terms, epipolar_terms, p, x0, x1, y0, y1, r.t, intensity, o)
                     : fusedEpipolarRowAvx512<kEpipolarLanes, kInterpolate, kIterations, false>(
                           n, terms, epipolar_terms, p, x0, x1, y0, y1, r.t, intensity, o);
        };
        if (iterations == 1) {
          u += r.interpolate ? row.template operator()<true, 1>()
                             : row.template operator()<false, 1>();
        } else {
          u += r.interpolate ? row.template operator()<true, 2>()
                             : row.template operator()<false, 2>();
        }
      }
      for (; u < width; ++u) scalar(u);
      continue;
    }
#endif
    const auto [rx, ry] = rowRays(v, rx_row, ry_row);
    // The fused loop wins without correction; with the along-ray correction
    // its register pressure makes row passes faster (bench_codecs,
    // BM_DecodeTriangulateAlongRay).
    if (iterations == 0) {
      depthRow<0>(first_row, second_row, first_is_column, second_is_column, rx, ry, nullptr, z_row);
    } else if (epipolar) {
      auto row = [&]<int kIterations>() {
        if (second >= 0) {
          epipolarDepthRow<kIterations, 2>(first_row, second_row, first_is_column, second_is_column,
                                           rx, ry, z_row);
        } else if (first == kColumn) {
          epipolarDepthRow<kIterations, kColumn>(first_row, second_row, first_is_column,
                                                 second_is_column, rx, ry, z_row);
        } else {
          epipolarDepthRow<kIterations, kRow>(first_row, second_row, first_is_column,
                                              second_is_column, rx, ry, z_row);
        }
      };
      if (iterations == 1) {
        row.template operator()<1>();
      } else if (iterations == 2) {
        row.template operator()<2>();
      } else {
        row.template operator()<-1>();
      }
    } else {
      depthRow<-1>(first_row, second_row, first_is_column, second_is_column, rx, ry, z_row + width,
                   z_row);
    }
    PointXYZI* __restrict out = cloud.points.data() + row_start;
    int u0 = 0;
#if defined(SL_HAVE_AVX512_POINTS)
    if (avx512_points) {
      // Up to 3 points to reach a cache-line boundary, then whole lines.
      const std::uintptr_t misalignment = reinterpret_cast<std::uintptr_t>(out) & 63;
      if ((misalignment & 15) == 0) {
        const int lead = std::min(width, static_cast<int>(((64 - misalignment) & 63) / 16));
        for (; u0 < lead; ++u0) {
          const float z = z_row[u0];
          out[u0] = PointXYZI{z * rx[u0], z * ry[u0], z, offset_row ? offset_row[u0] : 0.0f};
        }
        u0 += streamPointsAvx512(width - u0, z_row + u0, rx + u0, ry + u0,
                                 offset_row ? offset_row + u0 : nullptr, out + u0);
      }
    }
#endif
#if defined(__SSE2__)
    // The cloud (16 bytes per pixel) is the largest stream: write it with
    // non-temporal stores, which skip reading the lines first.
    if ((reinterpret_cast<std::uintptr_t>(out) & 15) == 0) {
      for (; u0 + 4 <= width; u0 += 4) {
        __m128 z = _mm_loadu_ps(z_row + u0);
        __m128 x = _mm_mul_ps(z, _mm_loadu_ps(rx + u0));
        __m128 y = _mm_mul_ps(z, _mm_loadu_ps(ry + u0));
        __m128 i = offset_row ? _mm_loadu_ps(offset_row + u0) : _mm_setzero_ps();
        _MM_TRANSPOSE4_PS(x, y, z, i);  // -> one point per register
        float* o = &out[u0].x;
        _mm_stream_ps(o, x);
        _mm_stream_ps(o + 4, y);
        _mm_stream_ps(o + 8, z);
        _mm_stream_ps(o + 12, i);
      }
    }
#endif
    for (int u = u0; u < width; ++u) {
      const float z = z_row[u];
      out[u] = PointXYZI{z * rx[u], z * ry[u], z, offset_row ? offset_row[u] : 0.0f};
    }
  }
#if defined(__SSE2__)
  _mm_sfence();  // the streamed points are visible before the caller reads them
#endif
}

}  // namespace sl::pipeline
