// Rendering of one camera image from the precomputed scene view: pattern
// sampling, ambient light, noise, ADC scaling and saturation.
#pragma once

#include <array>
#include <cstdint>
#include <vector>
#include <opencv2/core/mat.hpp>

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

// Light emitted by the projector per 8-bit pattern level, on the 0..255 scale
// (SimConfig::projector_gamma / projector_response); identity when linear.
struct ProjectorResponse {
  bool linear = true;
  std::array<float, 256> light{};  // light[L] for level L
};
// Throws std::invalid_argument naming the bad field.
ProjectorResponse makeProjectorResponse(double gamma, const std::vector<double>& samples);

// The camera image of one pattern frame. pattern_image is the projector image
// (CV_8UC1, maps.texture_width wide); the same seed gives the same image.
cv::Mat renderImage(const RenderMaps& maps, const cv::Mat& pattern_image,
                    const SensorResponse& response, std::uint64_t noise_seed,
                    const ProjectorResponse& projector = {});

}  // namespace sl::drivers::sim
