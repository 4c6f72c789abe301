#include "sim_render.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <vector>

#include "sl/pipeline/multiversion.h"

namespace sl::drivers::sim {

static_assert(std::endian::native == std::endian::little,
              "NormalSource reads hashes as 16-bit halves");

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

// The splitmix64 stream: out[k] = mix64(state + (k + 1) * golden), the
// same values the scalar stream gives one after another.
SL_MULTIVERSION void hashStream(std::uint64_t state, int words, std::uint64_t* __restrict out) {
  for (int k = 0; k < words; ++k) {
    std::uint64_t x = state + static_cast<std::uint64_t>(k + 1) * kGolden;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    out[k] = x ^ (x >> 31);
  }
}

// The hashes read as 16-bit halves (x86-64 is little-endian: the low half of
// each hash first); may_alias makes reading uint64_t storage this way defined.
using AliasingU16 = std::uint16_t __attribute__((may_alias));

SL_MULTIVERSION void lookUpNormals(const float* __restrict table,
                                   const AliasingU16* __restrict index, int count,
                                   float* __restrict out) {
  for (int i = 0; i < count; ++i) out[i] = table[index[i]];
}

// Noise-free signal (8-bit DN, before exposure and gain) of one row, from
// the 8-bit pattern image (kLinear = false: through the projector response,
// `light`) or, Texel = uint16_t, from the light image (1/256 units).
template <typename Texel, bool kLinear>
void signalRow(const RenderMaps& maps, const Texel* texture, const float* light, int row,
               float* signal) {
  const int width = maps.width;
  const std::ptrdiff_t stride = maps.texture_width;
  const std::size_t base = static_cast<std::size_t>(row) * width;
  const float* ambient = maps.ambient_dn.data() + base;
  const float* per_level = maps.projector_dn_per_level.data() + base;
  const std::int32_t* texel = maps.texel_index.data() + base;
  const float* wx = maps.weight_x.data() + base;
  const float* wy = maps.weight_y.data() + base;
  const float unit = sizeof(Texel) == 1 ? 1.0f : 1.0f / 256.0f;
  for (int c = 0; c < width; ++c) {
    const Texel* t = texture + texel[c];
    float t00 = t[0], t01 = t[1], t10 = t[stride], t11 = t[stride + 1];
    if constexpr (!kLinear) {
      t00 = light[t[0]];
      t01 = light[t[1]];
      t10 = light[t[stride]];
      t11 = light[t[stride + 1]];
    }
    const float top = t00 + wx[c] * (t01 - t00);
    const float bottom = t10 + wx[c] * (t11 - t10);
    const float level = top + wy[c] * (bottom - top);  // 0..255 (or * 256)
    signal[c] = ambient[c] + per_level[c] * unit * level;
  }
}

// Noise, exposure and gain, ADC scale, rounding and saturation of one row
// (no branches, vectorisable). z: standard normal variates (kNoise only).
template <typename Pixel, bool kNoise>
SL_MULTIVERSION void finishRow(const float* __restrict signal, const float* __restrict z,
                               const SensorResponse& r, int width, Pixel* __restrict dst) {
  const float scale = static_cast<float>(r.signal_scale);
  const float shot_gain = static_cast<float>(r.gain_dn_per_electron);
  const float read_variance = static_cast<float>(r.read_noise_dn * r.read_noise_dn);
  const float full_scale = static_cast<float>((1 << r.bit_depth) - 1);
  const float to_output = full_scale / 255.0f;
  // Round to nearest by truncating value + 0.5; the upper bound truncates to full scale.
  const float upper = full_scale + 0.5f;
  for (int c = 0; c < width; ++c) {
    float s = signal[c] * scale;
    if constexpr (kNoise) s += std::sqrt(shot_gain * s + read_variance) * z[c];
    const float value = std::min(std::max(s * to_output + 0.5f, 0.0f), upper);
    dst[c] = static_cast<Pixel>(static_cast<int>(value));
  }
}

// The camera's defocus on `signal` (camera size, CV_32FC1): `passes`
// passes of the separable 3-tap kernel [a, 1 - 2a, a] with each pixel's own
// a (variance 2a per pass and axis), gathering from its neighbours; image
// edges replicate.
void blurCameraImage(const RenderMaps& maps, int passes, cv::Mat& signal) {
  const int width = maps.width, height = maps.height;
  thread_local std::vector<float> line, previous;
  line.resize(static_cast<std::size_t>(width) + 2);
  previous.resize(static_cast<std::size_t>(width));
  for (int pass = 0; pass < passes; ++pass) {
    for (int row = 0; row < height; ++row) {  // along x
      float* s = signal.ptr<float>(row);
      const float* a = maps.camera_blur_a.data() + static_cast<std::size_t>(row) * width;
      std::copy(s, s + width, line.begin() + 1);
      line[0] = s[0];
      line[static_cast<std::size_t>(width) + 1] = s[width - 1];
      const float* l = line.data() + 1;
      for (int c = 0; c < width; ++c) s[c] = l[c] + a[c] * (l[c - 1] + l[c + 1] - 2 * l[c]);
    }
    // Along y, keeping the unfiltered previous row.
    std::copy(signal.ptr<float>(0), signal.ptr<float>(0) + width, previous.begin());
    for (int row = 0; row < height; ++row) {
      float* s = signal.ptr<float>(row);
      const float* below = signal.ptr<float>(std::min(row + 1, height - 1));
      const float* a = maps.camera_blur_a.data() + static_cast<std::size_t>(row) * width;
      float* above = previous.data();
      for (int c = 0; c < width; ++c) {
        const float centre = s[c];
        s[c] = centre + a[c] * (above[c] + below[c] - 2 * centre);
        above[c] = centre;
      }
    }
  }
}

// The noise-free signal (8-bit DN, camera blur applied) of one pattern frame
// into `signal` (CV_32FC1, camera size), row by row.
void signalInto(const RenderMaps& maps, const ProjectorFrame& frame,
                const ProjectorResponse& projector, int camera_blur_passes, cv::Mat& signal) {
  signal.create(maps.height, maps.width, CV_32FC1);
  for (int row = 0; row < maps.height; ++row) {
    float* out = signal.ptr<float>(row);
    if (!frame.light.empty())
      signalRow<std::uint16_t, true>(maps, frame.light.ptr<std::uint16_t>(), nullptr, row, out);
    else if (projector.linear)
      signalRow<std::uint8_t, true>(maps, frame.image.ptr<std::uint8_t>(), nullptr, row, out);
    else
      signalRow<std::uint8_t, false>(maps, frame.image.ptr<std::uint8_t>(), projector.light.data(),
                                     row, out);
  }
  if (camera_blur_passes > 0) blurCameraImage(maps, camera_blur_passes, signal);
}

// Noise, exposure, gain and ADC applied to a noise-free signal image.
template <typename Pixel, bool kNoise>
void finishInto(const cv::Mat& signal, const SensorResponse& r, std::uint64_t noise_seed,
                cv::Mat& out) {
  const int width = signal.cols;
  NormalSource normals(noise_seed);
  std::vector<float> z(kNoise ? width : 0);
  for (int row = 0; row < signal.rows; ++row) {
    if constexpr (kNoise) normals.fill(z.data(), width);
    finishRow<Pixel, kNoise>(signal.ptr<float>(row), z.data(), r, width, out.ptr<Pixel>(row));
  }
}

template <typename Pixel, bool kNoise>
void renderInto(const RenderMaps& maps, const ProjectorFrame& frame, const SensorResponse& r,
                const ProjectorResponse& projector, int camera_blur_passes,
                std::uint64_t noise_seed, cv::Mat& out) {
  const int width = maps.width;
  auto signalRowOf = [&](int row, float* signal) {
    if (!frame.light.empty())
      signalRow<std::uint16_t, true>(maps, frame.light.ptr<std::uint16_t>(), nullptr, row, signal);
    else if (projector.linear)
      signalRow<std::uint8_t, true>(maps, frame.image.ptr<std::uint8_t>(), nullptr, row, signal);
    else
      signalRow<std::uint8_t, false>(maps, frame.image.ptr<std::uint8_t>(), projector.light.data(),
                                     row, signal);
  };
  if (camera_blur_passes == 0) {
    // Row by row: the signal row stays in cache.
    NormalSource normals(noise_seed);
    std::vector<float> z(kNoise ? width : 0);
    std::vector<float> signal(width);
    for (int row = 0; row < maps.height; ++row) {
      signalRowOf(row, signal.data());
      if constexpr (kNoise) normals.fill(z.data(), width);
      finishRow<Pixel, kNoise>(signal.data(), z.data(), r, width, out.ptr<Pixel>(row));
    }
    return;
  }
  thread_local cv::Mat signal;
  signalInto(maps, frame, projector, camera_blur_passes, signal);
  finishInto<Pixel, kNoise>(signal, r, noise_seed, out);
}

}  // namespace

std::uint64_t mix64(std::uint64_t x) {
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

NormalSource::NormalSource(std::uint64_t seed) : state_(mix64(seed + kGolden)) {}

float normalQuantile(std::uint16_t index) { return normalTable()[index]; }

void NormalSource::fill(float* out, int count) {
  if (count <= 0) return;
  // Each hash gives four 16-bit table indices, low half first.
  const int words = (count + 3) / 4;
  thread_local std::vector<std::uint64_t> bits;
  if (bits.size() < static_cast<std::size_t>(words)) bits.resize(static_cast<std::size_t>(words));
  hashStream(state_, words, bits.data());
  state_ += kGolden * static_cast<std::uint64_t>(words);
  lookUpNormals(normalTable().data(), reinterpret_cast<const AliasingU16*>(bits.data()), count,
                out);
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
      if (!(v >= 0 && v <= 1))
        throw std::invalid_argument("projector_response values must be in [0, 1]");
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

cv::Mat renderImage(const RenderMaps& maps, const ProjectorFrame& frame,
                    const SensorResponse& response, std::uint64_t noise_seed,
                    const ProjectorResponse& projector, int camera_blur_passes) {
  const cv::Mat& texture = frame.light.empty() ? frame.image : frame.light;
  if (texture.type() != (frame.light.empty() ? CV_8UC1 : CV_16UC1) ||
      texture.cols != maps.texture_width || !texture.isContinuous())
    throw std::invalid_argument(
        "renderImage: pattern image must be continuous CV_8UC1 (light CV_16UC1) of the "
        "projector's width");
  if (camera_blur_passes > 0 && maps.camera_blur_a.size() != maps.ambient_dn.size())
    throw std::invalid_argument("renderImage: camera blur not assigned to the maps");
  const bool noise = response.gain_dn_per_electron > 0 || response.read_noise_dn > 0;
  cv::Mat out(maps.height, maps.width, response.bit_depth == 8 ? CV_8UC1 : CV_16UC1);
  auto run = [&]<typename Pixel>() {
    if (noise)
      renderInto<Pixel, true>(maps, frame, response, projector, camera_blur_passes, noise_seed,
                              out);
    else
      renderInto<Pixel, false>(maps, frame, response, projector, camera_blur_passes, noise_seed,
                               out);
  };
  if (response.bit_depth == 8)
    run.template operator()<std::uint8_t>();
  else
    run.template operator()<std::uint16_t>();
  return out;
}

cv::Mat renderImage(const RenderMaps& maps, const cv::Mat& pattern_image,
                    const SensorResponse& response, std::uint64_t noise_seed,
                    const ProjectorResponse& projector) {
  ProjectorFrame frame;
  frame.image = pattern_image;
  return renderImage(maps, frame, response, noise_seed, projector, 0);
}

cv::Mat renderSignal(const RenderMaps& maps, const ProjectorFrame& frame,
                     const ProjectorResponse& projector, int camera_blur_passes) {
  const cv::Mat& texture = frame.light.empty() ? frame.image : frame.light;
  if (texture.type() != (frame.light.empty() ? CV_8UC1 : CV_16UC1) ||
      texture.cols != maps.texture_width || !texture.isContinuous())
    throw std::invalid_argument(
        "renderSignal: pattern image must be continuous CV_8UC1 (light CV_16UC1) of the "
        "projector's width");
  if (camera_blur_passes > 0 && maps.camera_blur_a.size() != maps.ambient_dn.size())
    throw std::invalid_argument("renderSignal: camera blur not assigned to the maps");
  cv::Mat signal;
  signalInto(maps, frame, projector, camera_blur_passes, signal);
  return signal;
}

cv::Mat renderFromSignal(const cv::Mat& signal, const SensorResponse& response,
                         std::uint64_t noise_seed) {
  if (signal.type() != CV_32FC1)
    throw std::invalid_argument("renderFromSignal: signal must be CV_32FC1");
  const bool noise = response.gain_dn_per_electron > 0 || response.read_noise_dn > 0;
  cv::Mat out(signal.rows, signal.cols, response.bit_depth == 8 ? CV_8UC1 : CV_16UC1);
  auto run = [&]<typename Pixel>() {
    if (noise)
      finishInto<Pixel, true>(signal, response, noise_seed, out);
    else
      finishInto<Pixel, false>(signal, response, noise_seed, out);
  };
  if (response.bit_depth == 8)
    run.template operator()<std::uint8_t>();
  else
    run.template operator()<std::uint16_t>();
  return out;
}

void BlurLevels::locate(double sigma, int& k, float& weight) const {
  const std::size_t n = sigma_px.size();
  std::size_t i = 0;
  while (i + 2 < n && sigma_px[i + 1] <= sigma) ++i;
  k = static_cast<int>(i);
  const double v0 = sigma_px[i] * sigma_px[i], v1 = sigma_px[i + 1] * sigma_px[i + 1];
  weight = static_cast<float>(std::clamp((sigma * sigma - v0) / (v1 - v0), 0.0, 1.0));
}

BlurLevels chooseBlurLevels(double min_sigma, double max_sigma, double ratio, int max_levels) {
  BlurLevels levels;
  constexpr double kNegligible = 0.15, kFirstMax = 1.0;
  if (!(max_sigma >= kNegligible)) return levels;
  // 0, then the first level at max_sigma if that is within 1 px (a mild
  // blur: the blend of sharp and blurred is the Gaussian to second order),
  // else at 1 px and growing by `ratio`, enough that max_levels suffice.
  std::vector<double> all{0.0, std::min(max_sigma, kFirstMax)};
  ratio = std::max(ratio, std::pow(max_sigma / all.back(), 1.0 / std::max(max_levels - 2, 1)));
  while (all.back() < max_sigma * (1 - 1e-9))
    all.push_back(std::min(all.back() * ratio, max_sigma));
  // Keep the levels that bracket [min_sigma, max_sigma].
  std::size_t first = 0;
  while (first + 2 < all.size() && all[first + 1] <= min_sigma) ++first;
  levels.sigma_px.assign(all.begin() + static_cast<std::ptrdiff_t>(first), all.end());
  return levels;
}

ProjectorBlur makeProjectorBlur(const BlurLevels& levels, const cv::Mat& sigma_px) {
  ProjectorBlur blur;
  blur.levels = levels;
  if (!levels.active()) return blur;
  blur.level.create(sigma_px.size(), CV_8UC1);
  blur.weight.create(sigma_px.size(), CV_32FC1);
  for (int r = 0; r < sigma_px.rows; ++r) {
    const float* sigma = sigma_px.ptr<float>(r);
    std::uint8_t* level = blur.level.ptr<std::uint8_t>(r);
    float* weight = blur.weight.ptr<float>(r);
    for (int c = 0; c < sigma_px.cols; ++c) {
      int k = 0;
      levels.locate(sigma[c], k, weight[c]);
      level[c] = static_cast<std::uint8_t>(k);
    }
  }
  return blur;
}

ProjectorFrame makeProjectorFrame(const cv::Mat& pattern_image, const ProjectorResponse& response,
                                  const ProjectorBlur& blur) {
  ProjectorFrame frame;
  frame.image = pattern_image;
  if (!blur.levels.active()) return frame;
  cv::Mat light(pattern_image.size(), CV_32FC1);
  for (int r = 0; r < pattern_image.rows; ++r) {
    const std::uint8_t* in = pattern_image.ptr<std::uint8_t>(r);
    float* out = light.ptr<float>(r);
    for (int c = 0; c < pattern_image.cols; ++c) out[c] = response.light[in[c]];
  }
  std::vector<cv::Mat> copies;
  for (double sigma : blur.levels.sigma_px) {
    copies.emplace_back();
    // No light comes from outside the DMD: the border is dark.
    if (sigma > 0)
      cv::GaussianBlur(light, copies.back(), cv::Size(), sigma, sigma, cv::BORDER_CONSTANT);
    else
      copies.back() = light;
  }
  frame.light.create(pattern_image.size(), CV_16UC1);
  std::vector<const float*> rows(copies.size());
  for (int r = 0; r < pattern_image.rows; ++r) {
    for (std::size_t k = 0; k < copies.size(); ++k) rows[k] = copies[k].ptr<float>(r);
    const std::uint8_t* level = blur.level.ptr<std::uint8_t>(r);
    const float* weight = blur.weight.ptr<float>(r);
    std::uint16_t* out = frame.light.ptr<std::uint16_t>(r);
    if (copies.size() == 2) {  // the common case: one blend for the whole image
      const float* a = rows[0];
      const float* b = rows[1];
      for (int c = 0; c < pattern_image.cols; ++c)
        out[c] = static_cast<std::uint16_t>(256.0f * (a[c] + weight[c] * (b[c] - a[c])) + 0.5f);
      continue;
    }
    for (int c = 0; c < pattern_image.cols; ++c) {
      const float a = rows[level[c]][c], b = rows[level[c] + 1u][c];
      out[c] = static_cast<std::uint16_t>(256.0f * (a + weight[c] * (b - a)) + 0.5f);
    }
  }
  return frame;
}

int cameraBlurPasses(double max_sigma) {
  constexpr double kNegligible = 0.15, kMaxVariancePerPass = 0.64;
  if (!(max_sigma >= kNegligible)) return 0;
  return static_cast<int>(std::ceil(max_sigma * max_sigma / kMaxVariancePerPass));
}

void assignCameraBlur(RenderMaps& maps, int passes, const SimLens& lens, double fx_px) {
  const std::size_t n = maps.ambient_dn.size();
  maps.camera_blur_a.assign(n, 0.0f);
  for (std::size_t i = 0; i < n; ++i) {
    const float z = maps.camera_depth_mm[i];
    if (!(z > 0)) continue;  // no surface: no light to spread
    const double sigma = lens.blurSigmaPx(z, fx_px);
    // Variance sigma^2 per axis split over the passes; beyond the passes
    // planned for (a moving sensor) the kernel is kept non-negative.
    maps.camera_blur_a[i] = static_cast<float>(std::min(sigma * sigma / (2.0 * passes), 0.45));
  }
}

}  // namespace sl::drivers::sim
