// Branch-free single-precision atan2 for the decoder's inner loops (private).
#pragma once

#include <cmath>
#include <numbers>

namespace sl::pipeline::detail {

// Bound on |fastAtan2Positive(y, x) - atan2(y, x) mod 2*pi| for finite y, x in
// radians, including float rounding; checked in test_decoder.cpp. The
// polynomial alone is within 2.5e-7 rad of atan on [0, 1].
inline constexpr double kFastAtan2MaxError = 1e-6;

// atan(a) ~ a * (c0 + s * (c1 + ... + s * c6)), s = a^2, on [0, 1]: odd
// polynomial, coefficients fitted here (weighted least squares on Chebyshev
// nodes refined toward minimax). Shared with the AVX-512 row kernel.
inline constexpr float kFastAtanPoly[7] = {
    0.99999611156190582f,  -0.33317368071633807f,  0.19807815629970074f, -0.13233342169201967f,
    0.079623671863822756f, -0.033604219133644364f, 0.006811792603694437f};

// atan2(y, x) mapped to [0, 2*pi). Written without branches so that loops
// over rows vectorize; (0, 0) gives 0.
inline float fastAtan2Positive(float y, float x) {
  constexpr float kPi = std::numbers::pi_v<float>;
  constexpr float c0 = kFastAtanPoly[0], c1 = kFastAtanPoly[1], c2 = kFastAtanPoly[2],
                  c3 = kFastAtanPoly[3], c4 = kFastAtanPoly[4], c5 = kFastAtanPoly[5],
                  c6 = kFastAtanPoly[6];
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float hi = ax > ay ? ax : ay;
  const float lo = ax > ay ? ay : ax;
  const float a = lo / (hi > 0.0f ? hi : 1.0f);  // unconditional division: no branch
  const float s = a * a;
  float r = a * (c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * (c5 + s * c6))))));
  r = ay > ax ? 0.5f * kPi - r : r;  // first octant -> first quadrant
  r = x < 0.0f ? kPi - r : r;        // -> upper half plane
  r = y < 0.0f ? 2.0f * kPi - r : r; // -> [0, 2*pi]
  return r >= 2.0f * kPi ? 0.0f : r;
}

}  // namespace sl::pipeline::detail
