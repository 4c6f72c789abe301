#include "sim_render.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace sl::drivers::sim {

namespace {

constexpr int kTableBits = 16;
constexpr int kTableSize = 1 << kTableBits;
constexpr std::uint64_t kGolden = 0x9e3779b97f4a7c15ull;

double standardNormalCdf(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

// Quantiles of the standard normal at (i + 0.5) / N, rescaled to unit variance.
const std::array<float, kTableSize>& normalTable() {
  static const std::array<float, kTableSize> table = [] {
    std::array<double, kTableSize> q{};
    for (int i = 0; i < kTableSize / 2; ++i) {
      const double p = (i + 0.5) / kTableSize;  // < 0.5: the quantile is negative
      double lo = -10.0, hi = 0.0;
      for (int step = 0; step < 60 && hi - lo > 1e-12; ++step) {
        const double mid = 0.5 * (lo + hi);
        (standardNormalCdf(mid) < p ? lo : hi) = mid;
      }
      q[i] = 0.5 * (lo + hi);
      q[kTableSize - 1 - i] = -q[i];
    }
    double sum_sq = 0;
    for (double v : q) sum_sq += v * v;
    const double scale = 1.0 / std::sqrt(sum_sq / kTableSize);
    std::array<float, kTableSize> t{};
    for (int i = 0; i < kTableSize; ++i) t[i] = static_cast<float>(q[i] * scale);
    return t;
  }();
  return table;
}

// Per-pixel kernel. kNoise = false skips the noise draws (exact model values);
// kLinear = false maps each texel through the projector's response.
template <typename Pixel, bool kNoise, bool kLinear>
void renderRows(const RenderMaps& maps, const std::uint8_t* texture, const SensorResponse& r,
                const float* light, std::uint64_t noise_seed, cv::Mat& out) {
  const int width = maps.width;
  const std::ptrdiff_t stride = maps.texture_width;
  const float scale = static_cast<float>(r.signal_scale);
  const float shot_gain = static_cast<float>(r.gain_dn_per_electron);
  const float read_variance = static_cast<float>(r.read_noise_dn * r.read_noise_dn);
  const float full_scale = static_cast<float>((1 << r.bit_depth) - 1);
  const float to_output = full_scale / 255.0f;
  // Round to nearest by truncating value + 0.5; the upper bound truncates to full scale.
  const float upper = full_scale + 0.5f;

  NormalSource normals(noise_seed);
  std::vector<float> signal(width);
  std::vector<float> z(kNoise ? width : 0);
  for (int row = 0; row < maps.height; ++row) {
    const std::size_t base = static_cast<std::size_t>(row) * width;
    const float* ambient = maps.ambient_dn.data() + base;
    const float* per_level = maps.projector_dn_per_level.data() + base;
    const std::int32_t* texel = maps.texel_index.data() + base;
    const float* wx = maps.weight_x.data() + base;
    const float* wy = maps.weight_y.data() + base;
    // Pass 1 (gathers, scalar): noise-free signal in 8-bit DN.
    for (int c = 0; c < width; ++c) {
      const std::uint8_t* t = texture + texel[c];
      float t00 = t[0], t01 = t[1], t10 = t[stride], t11 = t[stride + 1];
      if constexpr (!kLinear) {
        t00 = light[t[0]];
        t01 = light[t[1]];
        t10 = light[t[stride]];
        t11 = light[t[stride + 1]];
      }
      const float top = t00 + wx[c] * (t01 - t00);
      const float bottom = t10 + wx[c] * (t11 - t10);
      const float level = top + wy[c] * (bottom - top);  // 0..255
      signal[c] = (ambient[c] + per_level[c] * level) * scale;
    }
    // Pass 2 (no branches, vectorisable): noise, ADC scale, rounding, saturation.
    if constexpr (kNoise) normals.fill(z.data(), width);
    Pixel* dst = out.ptr<Pixel>(row);
    for (int c = 0; c < width; ++c) {
      float s = signal[c];
      if constexpr (kNoise) s += std::sqrt(shot_gain * s + read_variance) * z[c];
      const float value = std::min(std::max(s * to_output + 0.5f, 0.0f), upper);
      dst[c] = static_cast<Pixel>(static_cast<int>(value));
    }
  }
}

}  // namespace

std::uint64_t mix64(std::uint64_t x) {
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

NormalSource::NormalSource(std::uint64_t seed) : state_(mix64(seed + kGolden)) {}

void NormalSource::fill(float* out, int count) {
  const float* table = normalTable().data();
  int i = 0;
  for (; i + 4 <= count; i += 4) {
    state_ += kGolden;
    const std::uint64_t bits = mix64(state_);
    out[i] = table[bits & 0xffff];
    out[i + 1] = table[(bits >> 16) & 0xffff];
    out[i + 2] = table[(bits >> 32) & 0xffff];
    out[i + 3] = table[bits >> 48];
  }
  if (i < count) {
    state_ += kGolden;
    std::uint64_t bits = mix64(state_);
    for (; i < count; ++i, bits >>= 16) out[i] = table[bits & 0xffff];
  }
}

ProjectorResponse makeProjectorResponse(double gamma, const std::vector<double>& samples) {
  if (!(gamma > 0 && std::isfinite(gamma)))
    throw std::invalid_argument("projector_gamma must be finite and > 0");
  ProjectorResponse r;
  if (!samples.empty()) {
    if (gamma != 1.0)
      throw std::invalid_argument("projector_gamma must be 1 when projector_response is given");
    if (samples.size() < 2)
      throw std::invalid_argument("projector_response needs at least 2 samples");
    for (double v : samples)
      if (!(v >= 0 && v <= 1)) throw std::invalid_argument("projector_response values must be in [0, 1]");
  }
  for (int level = 0; level < 256; ++level) {
    double fraction = level / 255.0;
    if (!samples.empty()) {
      const double x = fraction * static_cast<double>(samples.size() - 1);
      const std::size_t k = std::min(static_cast<std::size_t>(x), samples.size() - 2);
      fraction = samples[k] + (x - static_cast<double>(k)) * (samples[k + 1] - samples[k]);
    } else if (gamma != 1.0) {
      fraction = std::pow(fraction, gamma);
    }
    r.light[level] = static_cast<float>(255.0 * fraction);
    // Linear means exactly the level itself (the fast path reads texels directly).
    if (std::abs(r.light[level] - static_cast<float>(level)) > 1e-4f) r.linear = false;
  }
  return r;
}

cv::Mat renderImage(const RenderMaps& maps, const cv::Mat& pattern_image,
                    const SensorResponse& response, std::uint64_t noise_seed,
                    const ProjectorResponse& projector) {
  if (pattern_image.type() != CV_8UC1 || pattern_image.cols != maps.texture_width ||
      !pattern_image.isContinuous())
    throw std::invalid_argument(
        "renderImage: pattern image must be continuous CV_8UC1 of the "
        "projector's width");
  const bool noise = response.gain_dn_per_electron > 0 || response.read_noise_dn > 0;
  const std::uint8_t* texture = pattern_image.ptr<std::uint8_t>();
  const float* light = projector.light.data();
  cv::Mat out(maps.height, maps.width, response.bit_depth == 8 ? CV_8UC1 : CV_16UC1);
  auto run = [&]<typename Pixel>() {
    if (noise && projector.linear)
      renderRows<Pixel, true, true>(maps, texture, response, light, noise_seed, out);
    else if (noise)
      renderRows<Pixel, true, false>(maps, texture, response, light, noise_seed, out);
    else if (projector.linear)
      renderRows<Pixel, false, true>(maps, texture, response, light, noise_seed, out);
    else
      renderRows<Pixel, false, false>(maps, texture, response, light, noise_seed, out);
  };
  if (response.bit_depth == 8)
    run.template operator()<std::uint8_t>();
  else
    run.template operator()<std::uint16_t>();
  return out;
}

}  // namespace sl::drivers::sim
