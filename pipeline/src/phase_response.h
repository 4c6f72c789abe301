// Phase correction for a non-linear projector (private to the pipeline).
//
// An N-step (or 2+1) phase computed from camera intensities I_n = a R(L_n) +
// b, where L_n = offset + amplitude cos(phi - delta_n) is the projected
// relative intensity and R the projector's response, does not depend on the
// pixel's gain a or ambient b: it is psi = g(phi) for one periodic function g
// per set. For a monotonic g the true phase is g^-1(psi); the table holds
// g^-1(psi) - psi on a uniform grid of psi over one period.
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

namespace sl::pipeline::detail {

// R(L) for L in [0, 1] from `response` (samples at L = k / (size - 1),
// linear in between).
inline double responseAt(const std::vector<float>& response, double level) {
  const double t = std::clamp(level, 0.0, 1.0) * static_cast<double>(response.size() - 1);
  const std::size_t k = std::min(static_cast<std::size_t>(t), response.size() - 2);
  const double f = t - static_cast<double>(k);
  return (1.0 - f) * response[k] + f * response[k + 1];
}

struct PhaseCorrection {
  static constexpr int kSize = 4096;  // grid steps over [0, 2 pi)
  std::vector<float> delta;           // kSize + 1 entries, rad

  // Corrected phase in [0, 2 pi) of a measured phase psi in [0, 2 pi).
  float apply(float psi) const {
    constexpr float kTwoPi = 2.0f * std::numbers::pi_v<float>;
    const float t = psi * (kSize / kTwoPi);
    int k = static_cast<int>(t);
    k = k < 0 ? 0 : (k >= kSize ? kSize - 1 : k);
    const float f = t - static_cast<float>(k);
    float phi = psi + (1.0f - f) * delta[k] + f * delta[k + 1];
    phi = phi < 0.0f ? phi + kTwoPi : phi;
    return phi >= kTwoPi ? phi - kTwoPi : phi;
  }
};

// The table of one set whose frames have phase shifts delta_n (weights ws =
// sin, wc = cos) and, for 2+1, a flat frame at `offset` subtracted with
// weights sum_ws, sum_wc (flat = false: none). Throws std::invalid_argument
// when g is not monotonic (the response too far from linear to invert).
inline PhaseCorrection makePhaseCorrection(const std::vector<float>& response, double offset,
                                           double amplitude, const std::vector<double>& deltas,
                                           bool flat, const std::string& who) {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  constexpr int kFine = 4 * PhaseCorrection::kSize;
  const double flat_value = flat ? responseAt(response, offset) : 0.0;
  double sum_ws = 0, sum_wc = 0;
  for (double d : deltas) {
    sum_ws += std::sin(d);
    sum_wc += std::cos(d);
  }
  // psi(phi) on a fine grid of phi, unwrapped to a continuous curve.
  std::vector<double> psi(kFine + 1);
  double previous = 0;
  for (int i = 0; i <= kFine; ++i) {
    const double phi = kTwoPi * i / kFine;
    double s = 0, c = 0;
    for (double d : deltas) {
      const double v = responseAt(response, offset + amplitude * std::cos(phi - d));
      s += std::sin(d) * v;
      c += std::cos(d) * v;
    }
    s -= sum_ws * flat_value;
    c -= sum_wc * flat_value;
    double p = std::atan2(s, c);
    if (i == 0) {
      p = p < -1.0 ? p + kTwoPi : p;  // near 0 for a near-linear response
    } else {
      p += kTwoPi * std::round((previous - p) / kTwoPi);
      if (!(p > previous))
        throw std::invalid_argument(who + ": the projector response is too far from linear to "
                                          "compensate (the measured phase is not monotonic)");
    }
    psi[i] = previous = p;
  }
  if (std::abs(psi[kFine] - psi[0] - kTwoPi) > 1e-6)
    throw std::invalid_argument(who + ": the projector response does not give one phase period");
  // Invert: for psi_k on a uniform grid, the phi with psi(phi) = psi_k.
  PhaseCorrection table;
  table.delta.resize(PhaseCorrection::kSize + 1);
  int i = 0;
  for (int k = 0; k <= PhaseCorrection::kSize; ++k) {
    // psi_k in the curve's range [psi[0], psi[0] + 2 pi].
    double target = kTwoPi * k / PhaseCorrection::kSize;
    target += kTwoPi * std::ceil((psi[0] - target) / kTwoPi);
    while (i < kFine - 1 && psi[i + 1] < target) ++i;
    while (i > 0 && psi[i] > target) --i;
    const double f = (target - psi[i]) / (psi[i + 1] - psi[i]);
    const double phi = kTwoPi * (i + f) / kFine;
    table.delta[k] = static_cast<float>(
        std::remainder(phi - kTwoPi * k / PhaseCorrection::kSize, kTwoPi));
  }
  return table;
}

}  // namespace sl::pipeline::detail
