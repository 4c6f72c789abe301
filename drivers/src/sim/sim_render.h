// Rendering of one camera image from the precomputed scene view: pattern
// sampling, ambient light, noise, ADC scaling and saturation.
#pragma once

#include <array>
#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <vector>

#include "sim_scene.h"

namespace sl::drivers::sim {

// Camera noise and ADC. Signal and noise are in 8-bit DN (full scale 255)
// whatever the bit depth; see SimConfig.
struct SensorResponse {
  double signal_scale = 1;          // exposure / reference exposure * analog gain
  double gain_dn_per_electron = 0;  // shot noise variance per DN of (scaled) signal
  double read_noise_dn = 0;         // std of the signal-independent noise
  int bit_depth = 8;                // output: 8 -> CV_8UC1, 9..16 -> CV_16UC1
};

// Standard normal variates from a 64-bit seed, fast enough for one draw per
// pixel at video rate: a splitmix64 stream indexes a table of 2^16 normal
// quantiles (rescaled to unit variance; tails end at about 4.3 sigma).
// Thread-compatible (the shared table is immutable once built).
class NormalSource {
 public:
  explicit NormalSource(std::uint64_t seed);
  // Writes `count` variates to `out`.
  void fill(float* out, int count);

 private:
  std::uint64_t state_;
};

// splitmix64 finaliser: a well-mixed 64-bit hash of x.
std::uint64_t mix64(std::uint64_t x);

// NormalSource's table: the standard normal quantile at (index + 0.5) / 2^16,
// rescaled to unit variance. Variate i of a fill() is normalQuantile of the
// (i % 4)-th 16-bit half (lowest first) of mix64(s + (i / 4 + 1) * 0x9e3779b97f4a7c15),
// s the source's state before the call, mix64(seed + 0x9e3779b97f4a7c15) for a new one;
// each fill() advances the state by one step per started group of four.
float normalQuantile(std::uint16_t index);

// Light emitted by the projector per 8-bit pattern level, on the 0..255 scale
// (SimConfig::projector_gamma / projector_response); identity when linear.
struct ProjectorResponse {
  bool linear = true;
  std::array<float, 256> light{};  // light[L] for level L
};
// Throws std::invalid_argument naming the bad field.
ProjectorResponse makeProjectorResponse(double gamma, const std::vector<double>& samples);

// Defocus blur levels of the projector: Gaussian sigmas (px, ascending) at
// which blurred copies of each pattern are made. A pixel whose sigma lies between two levels
// gets the blend of those two copies, linear in variance (exact for the
// Gaussian MTF to first order); outside the range it is clamped to the end
// levels. Inactive (no blur anywhere) with fewer than two levels.
struct BlurLevels {
  std::vector<double> sigma_px;

  bool active() const { return sigma_px.size() >= 2; }
  // Lower level k in [0, size - 2] and the weight of level k + 1.
  void locate(double sigma, int& k, float& weight) const;
};

// Levels covering sigmas in [min_sigma, max_sigma]: 0, then min(max_sigma,
// 1 px), then growing by `ratio` (or faster, so that at most max_levels are
// used) up to max_sigma; only those bracketing the range are kept. Inactive
// when max_sigma < 0.15 px (a blur that small changes nothing a pixel grid
// can show).
BlurLevels chooseBlurLevels(double min_sigma, double max_sigma, double ratio, int max_levels);

// A pattern frame as the renderer samples it. Without projector blur: the
// 8-bit projector image (the response is applied per texel). With it: the
// light the projector sends through each pixel's direction (response
// applied, 0..255 in units of 1/256), blurred by the projector's defocus.
struct ProjectorFrame {
  cv::Mat image;  // CV_8UC1 pattern levels
  cv::Mat light;  // CV_16UC1 light * 256, or empty (then image is sampled)
};

// The projector's defocus in projector space: the light of each pixel p is
// the pattern blurred by a Gaussian of sigma(p), the sigma for the depth of
// the surface p lights. Blurred copies are made at each of the levels and
// blended per pixel, linear in variance: the per-pixel blend is computed
// once (level k and the weight of k + 1) and serves every pattern image.
struct ProjectorBlur {
  BlurLevels levels;  // inactive: no blur
  cv::Mat level;      // CV_8UC1, projector size
  cv::Mat weight;     // CV_32FC1
};
// sigma_px: CV_32FC1 of the projector's size (0 where nothing is lit).
ProjectorBlur makeProjectorBlur(const BlurLevels& levels, const cv::Mat& sigma_px);
// Inactive blur: a frame without light image (the pattern is sampled).
ProjectorFrame makeProjectorFrame(const cv::Mat& pattern_image, const ProjectorResponse& response,
                                  const ProjectorBlur& blur);

// Camera blur: passes of a per-pixel 3-tap kernel [a, 1 - 2a, a] along x
// and y (variance 2a each), repeated often enough that a <= 0.32: a Gaussian
// of variance sigma^2 to second order, and cheap for the fraction of a pixel
// a mild defocus spreads. 0 passes below sigma 0.15 px (no blur).
int cameraBlurPasses(double max_sigma);
// Sets maps.camera_blur_a from the camera depths: a = sigma^2 / (2 passes).
void assignCameraBlur(RenderMaps& maps, int passes, const SimLens& lens, double fx_px);

// The camera image of one pattern frame; the same seed gives the same
// image. camera_blur_passes: as assignCameraBlur used (0: sharp).
cv::Mat renderImage(const RenderMaps& maps, const ProjectorFrame& frame,
                    const SensorResponse& response, std::uint64_t noise_seed,
                    const ProjectorResponse& projector = {}, int camera_blur_passes = 0);
// Unblurred 8-bit pattern image: the same as a ProjectorFrame without light.
cv::Mat renderImage(const RenderMaps& maps, const cv::Mat& pattern_image,
                    const SensorResponse& response, std::uint64_t noise_seed,
                    const ProjectorResponse& projector = {});

// renderImage in two steps, for a static scene whose noise-free signal is
// computed once per pattern frame: renderFromSignal(renderSignal(...), r, seed)
// is bit for bit renderImage(maps, frame, r, seed, projector, passes).
// renderSignal: CV_32FC1 of the camera's size, 8-bit DN before exposure,
// gain and noise.
cv::Mat renderSignal(const RenderMaps& maps, const ProjectorFrame& frame,
                     const ProjectorResponse& projector = {}, int camera_blur_passes = 0);
cv::Mat renderFromSignal(const cv::Mat& signal, const SensorResponse& response,
                         std::uint64_t noise_seed);

}  // namespace sl::drivers::sim
