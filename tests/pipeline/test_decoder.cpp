// PhaseShift33Decoder against analytic ground truth: images are rendered here
// from a known map camera pixel -> projector coordinate with patternIntensity()
// and known A, B, then decoded and compared.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include <catch2/catch.hpp>
#include <opencv2/core.hpp>

#include "../../pipeline/src/fast_atan2.h"  // white-box: the error bound of the fast atan2
#include "../../pipeline/src/two_three_step_row.h"  // white-box: AVX-512 vs portable 3+3 row
#include "sl/pipeline/decoder.h"

using namespace sl::pipeline;

namespace {

constexpr double kPi = std::numbers::pi;

struct ProjectorPoint {
  double u, v;  // projector px
};

// What the camera sees at pixel (u, v) in frame `frame`.
using Field = std::function<ProjectorPoint(int u, int v, int frame)>;
using Level = std::function<double(int u, int v)>;  // camera DN

// I = A + B cos(phi - shift) = A + B (2 * patternIntensity - 1), rounded and
// clipped to the bit depth, stored as CV_16UC1 (bit_depth > 8) or CV_8UC1.
std::vector<cv::Mat> render(const PhaseShift33Pattern& pattern, cv::Size size, int bit_depth,
                            const Field& field, const Level& offset, const Level& modulation) {
  const double max_value = std::ldexp(1.0, bit_depth) - 1.0;
  std::vector<cv::Mat> frames;
  for (int f = 0; f < pattern.frameCount(); ++f) {
    cv::Mat image(size, bit_depth > 8 ? CV_16UC1 : CV_8UC1);
    for (int v = 0; v < size.height; ++v) {
      for (int u = 0; u < size.width; ++u) {
        const ProjectorPoint p = field(u, v, f);
        const double value = offset(u, v) + modulation(u, v) *
                                                (2.0 * patternIntensity(pattern, f, p.u, p.v) - 1.0);
        const double q = std::clamp(std::round(value), 0.0, max_value);
        if (image.depth() == CV_16U) {
          image.at<std::uint16_t>(v, u) = static_cast<std::uint16_t>(q);
        } else {
          image.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(q);
        }
      }
    }
    frames.push_back(image);
  }
  return frames;
}

// A smooth, monotone, slightly nonlinear map covering the projector:
// columns depend mostly on u, rows mostly on v; both stay in
// [margin, L - 0.5 - margin], inside the decodable range [0, L - 0.5].
ProjectorPoint groundTruth(const PhaseShift33Pattern& p, cv::Size size, int u, int v,
                           double margin = 0.05) {
  const double s = (u + 0.25 * v) / ((size.width - 1) + 0.25 * (size.height - 1));
  const double t = (v + 0.2 * u) / ((size.height - 1) + 0.2 * (size.width - 1));
  const double fs = s + 0.04 * std::sin(2 * kPi * s);
  const double ft = t - 0.03 * std::sin(2 * kPi * t);
  return {margin + (p.projector_width - 0.5 - 2 * margin) * fs,
          margin + (p.projector_height - 0.5 - 2 * margin) * ft};
}

// Worst-case phase error from rounding each frame to +-0.5 DN: the vector
// (sqrt(3)(I1 - I2), 2 I0 - I1 - I2) of length 3B moves by at most
// sqrt(3 * 1^2 + 2^2) = sqrt(7), so |d phi| <= sqrt(7) / (3 B).
double quantisationBoundPx(double wavelength, double min_b, double axis_length) {
  const double phase = std::sqrt(7.0) / (3.0 * min_b) + detail::kFastAtan2MaxError;
  const double float_rounding = 4.0 * axis_length * std::numeric_limits<float>::epsilon();
  return wavelength / (2 * kPi) * phase + float_rounding;
}

bool isNaN(float x) { return std::isnan(x); }

PixelStatus statusAt(const ProjectorMaps& m, int u, int v) {
  return static_cast<PixelStatus>(m.status.at<std::uint8_t>(v, u));
}

}  // namespace

TEST_CASE("fast atan2 stays within its documented bound", "[decoder]") {
  double max_error = 0;
  int outside = 0;
  const int steps = 200000;
  for (double radius : {1e-3, 1.0, 3.0, 1234.5, 6.0e4}) {
    for (int i = 0; i <= steps; ++i) {
      const double angle = 2 * kPi * i / steps;
      const float y = static_cast<float>(radius * std::sin(angle));
      const float x = static_cast<float>(radius * std::cos(angle));
      const double fast = detail::fastAtan2Positive(y, x);
      if (!(fast >= 0.0 && fast < 2 * kPi)) ++outside;
      double diff = std::remainder(fast - std::atan2(double(y), double(x)), 2 * kPi);
      max_error = std::max(max_error, std::abs(diff));
    }
  }
  // Axes and the origin exactly.
  CHECK(detail::fastAtan2Positive(0.0f, 1.0f) == 0.0f);
  CHECK(detail::fastAtan2Positive(0.0f, 0.0f) == 0.0f);
  CHECK(detail::fastAtan2Positive(-0.0f, 5.0f) == 0.0f);
  CHECK(std::abs(detail::fastAtan2Positive(1.0f, 0.0f) - kPi / 2) < 1e-6);
  CHECK(std::abs(detail::fastAtan2Positive(0.0f, -1.0f) - kPi) < 1e-6);
  CHECK(std::abs(detail::fastAtan2Positive(-1.0f, 0.0f) - 1.5 * kPi) < 1e-6);
  // Measured: 7.3e-7 rad, mostly float rounding of results near 2*pi.
  CAPTURE(max_error);
  CHECK(outside == 0);
  CHECK(max_error < detail::kFastAtan2MaxError);
}

TEST_CASE("AVX-512 3+3 row kernel matches the portable one bit for bit", "[decoder]") {
  if (!detail::twoThreeStepAvx512Supported()) {
    WARN("CPU without AVX-512: nothing to compare");
    return;
  }
  std::mt19937 rng(20261123);
  auto uniform = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  const int max_width = 1000 + 13;
  std::vector<std::vector<std::uint8_t>> frames(6, std::vector<std::uint8_t>(max_width));
  struct Maps {
    std::vector<float> coord, modulation, offset, residual, scratch;
    std::vector<std::uint8_t> status;
    explicit Maps(int n)
        : coord(n), modulation(n), offset(n), residual(n), scratch(n), status(n) {}
    detail::TwoThreeStepOutput out() {
      return {coord.data(),  modulation.data(), offset.data(),
              status.data(), residual.data(),   scratch.data()};
    }
  };
  auto same = [](const std::vector<float>& a, const std::vector<float>& b, int n) {
    return std::memcmp(a.data(), b.data(), sizeof(float) * n) == 0;
  };
  int rows = 0, differing_rows = 0;
  std::vector<int> status_count(5, 0);
  for (double start : {0.0, 0.3, -2.0}) {
    for (int sign : {1, -1}) {
      detail::TwoThreeStepParams p;
      for (int n = 0; n < 3; ++n) {
        const double fine_delta = start + sign * 2.0 * kPi * n / 3;
        const double coarse_delta = 0.5 * start + sign * 2.0 * kPi * n / 3;
        p.fine.ws[n] = static_cast<float>(std::sin(fine_delta));
        p.fine.wc[n] = static_cast<float>(std::cos(fine_delta));
        p.coarse.ws[n] = static_cast<float>(std::sin(coarse_delta));
        p.coarse.wc[n] = static_cast<float>(std::cos(coarse_delta));
      }
      p.fine.scale2 = p.coarse.scale2 = (2.0f / 3.0f) * (2.0f / 3.0f);
      p.offset_from_fine = sign > 0;
      const float axis = start == 0.0 ? 1824.0f : 1140.0f;
      p.k.ratio = start < 0 ? 8.0f : 16.0f;
      p.k.to_px = static_cast<float>(axis / (2.0 * kPi * p.k.ratio));
      p.k.period = axis;
      p.k.inv_period = 1.0f / p.k.period;
      p.k.max_coord = axis - 0.5f;
      p.k.min_b2 = 64.0f;
      p.k.max_err = 0.35f;
      for (float saturation : {255.0f, std::numeric_limits<float>::infinity(), 200.5f}) {
        p.k.saturation = saturation;
        for (int width : {1, 15, 16, 17, 63, 64, 65, 250, max_width}) {
          // Fringes with noise, plus stretches of: uniform noise, equal frames
          // (no modulation), 0 / 255 extremes, saturated single frames.
          const double fine_period = uniform(6, 40), phase0 = uniform(0, 628) / 100.0;
          for (int x = 0; x < width; ++x) {
            const int kind = (x / 37 + rows) % 6;
            const int level = uniform(0, 255);
            for (int f = 0; f < 6; ++f) {
              const double cycles = f < 3 ? x / fine_period : x / (fine_period * p.k.ratio);
              const double phase = 2.0 * kPi * cycles + phase0 - sign * 2.0 * kPi * (f % 3) / 3;
              double value = 128 + 110 * std::cos(phase) + uniform(-3, 3);
              if (kind == 1) value = uniform(0, 255);
              if (kind == 2) value = level;
              if (kind == 3) value = uniform(0, 1) * 255;
              if (kind == 4 && uniform(0, 5) == 0) value = 255;
              frames[f][x] = static_cast<std::uint8_t>(std::clamp(value, 0.0, 255.0));
            }
          }
          const std::uint8_t* in[6];
          for (int f = 0; f < 6; ++f) in[f] = frames[f].data();
          Maps portable(width), avx512(width);
          detail::twoThreeStepRow(p, in, width, portable.out());
          detail::twoThreeStepRowAvx512(p, in, width, avx512.out());
          ++rows;
          const bool equal = same(portable.coord, avx512.coord, width) &&
                             same(portable.modulation, avx512.modulation, width) &&
                             same(portable.offset, avx512.offset, width) &&
                             same(portable.residual, avx512.residual, width) &&
                             portable.status == avx512.status;
          if (!equal) ++differing_rows;
          for (int x = 0; x < width; ++x) ++status_count[std::min<int>(portable.status[x], 4)];
        }
      }
    }
  }
  CAPTURE(rows, status_count);
  CHECK(differing_rows == 0);
  // Every status the kernel can give occurred (valid, low modulation,
  // saturated, unwrapping error, out of range).
  for (int count : status_count) CHECK(count > 0);
}

TEST_CASE("decoder recovers an analytic projector map (16-bit)", "[decoder]") {
  const Direction direction =
      GENERATE(Direction::kHorizontal, Direction::kVertical, Direction::kBoth);
  const int fringes = GENERATE(4, 8, 16, 32, 64);
  PhaseShift33Pattern pattern;
  pattern.direction = direction;
  pattern.fringes = fringes;
  const cv::Size size(320, 240);
  const double min_b = 14000;
  const Level offset = [&](int u, int) { return 20000.0 + 6000.0 * u / size.width; };
  const Level modulation = [&](int, int v) { return min_b + 4000.0 * v / size.height; };
  const Field field = [&](int u, int v, int) { return groundTruth(pattern, size, u, v); };
  const auto frames = render(pattern, size, 16, field, offset, modulation);

  const PhaseShift33Decoder decoder(pattern, DecoderOptions{});
  const ProjectorMaps maps = decoder.decode(frames, 16);
  REQUIRE(maps.up.size() == size);
  REQUIRE(maps.vp.size() == size);
  REQUIRE(maps.modulation.size() == size);
  REQUIRE(maps.offset.size() == size);
  REQUIRE(maps.status.size() == size);

  const bool columns = direction != Direction::kVertical;
  const bool rows = direction != Direction::kHorizontal;
  const double bound_u =
      quantisationBoundPx(pattern.wavelength(pattern.projector_width), min_b,
                          pattern.projector_width);
  const double bound_v =
      quantisationBoundPx(pattern.wavelength(pattern.projector_height), min_b,
                          pattern.projector_height);
  double max_error_u = 0, max_error_v = 0, max_error_a = 0, max_error_b = 0;
  int invalid = 0, unexpected_nan = 0, unexpected_value = 0;
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      if (statusAt(maps, u, v) != PixelStatus::kValid) ++invalid;
      const ProjectorPoint truth = groundTruth(pattern, size, u, v);
      const float up = maps.up.at<float>(v, u);
      const float vp = maps.vp.at<float>(v, u);
      if (columns) {
        if (isNaN(up)) ++unexpected_nan;
        else max_error_u = std::max(max_error_u, std::abs(up - truth.u));
      } else if (!isNaN(up)) {
        ++unexpected_value;
      }
      if (rows) {
        if (isNaN(vp)) ++unexpected_nan;
        else max_error_v = std::max(max_error_v, std::abs(vp - truth.v));
      } else if (!isNaN(vp)) {
        ++unexpected_value;
      }
      max_error_a = std::max(max_error_a, std::abs(maps.offset.at<float>(v, u) - offset(u, v)));
      max_error_b =
          std::max(max_error_b, std::abs(maps.modulation.at<float>(v, u) - modulation(u, v)));
    }
  }
  CAPTURE(toString(direction), fringes, max_error_u, bound_u, max_error_v, bound_v, max_error_a,
          max_error_b);
  CHECK(invalid == 0);
  CHECK(unexpected_nan == 0);
  CHECK(unexpected_value == 0);
  CHECK(max_error_u <= bound_u);
  CHECK(max_error_v <= bound_v);
  // A is the mean of three values rounded by +-0.5; B moves by sqrt(7)/3.
  CHECK(max_error_a <= 0.5 + 1e-3);
  CHECK(max_error_b <= std::sqrt(7.0) / 3.0 + 1e-2);
}

TEST_CASE("decoder on 8-bit frames stays within the 8-bit quantisation bound", "[decoder]") {
  PhaseShift33Pattern pattern;
  pattern.fringes = GENERATE(8, 16);
  const cv::Size size(320, 240);
  const double min_b = 80;
  const Level offset = [](int, int) { return 120.0; };
  const Level modulation = [&](int u, int) { return min_b + 20.0 * u / size.width; };
  // 8-bit errors reach a few tenths of a px: keep 1 px away from the range ends.
  const Field field = [&](int u, int v, int) { return groundTruth(pattern, size, u, v, 1.0); };
  const auto frames = render(pattern, size, 8, field, offset, modulation);
  const ProjectorMaps maps = PhaseShift33Decoder(pattern, {}).decode(frames, 8);
  const double bound = quantisationBoundPx(pattern.wavelength(pattern.projector_width), min_b,
                                           pattern.projector_width);
  double max_error = 0;
  int invalid = 0;
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      const float up = maps.up.at<float>(v, u);
      if (isNaN(up)) {
        ++invalid;
        continue;
      }
      max_error = std::max(max_error, std::abs(up - groundTruth(pattern, size, u, v, 1.0).u));
    }
  }
  CAPTURE(pattern.fringes, max_error, bound);
  CHECK(invalid == 0);
  CHECK(max_error <= bound);
}

TEST_CASE("decoder marks each invalid reason", "[decoder]") {
  PhaseShift33Pattern pattern;
  pattern.fringes = 16;
  const double lambda = pattern.wavelength(pattern.projector_width);
  const double L = pattern.projector_width;
  const cv::Size size(160, 120);
  // Column bands of the camera image, one per reason; rows 0..59 use the
  // smooth ground truth, rows 60.. are constant coordinates for the range test.
  const Level offset = [](int, int) { return 30000.0; };
  // Threshold (set below, not the default): 8 DN at 8 bits = 2048 DN at 16
  // bits. B is recovered to +-0.9 DN, so 2100 must pass and 1990 must fail.
  DecoderOptions options;
  options.min_modulation = 8;
  const Level modulation = [](int u, int) {
    if (u >= 10 && u < 15) return 1990.0;
    if (u >= 15 && u < 20) return 2100.0;
    return 20000.0;
  };
  const Field field = [&](int u, int v, int frame) {
    ProjectorPoint p = groundTruth(pattern, size, u, v);
    if (v >= 60 && u < 80) p.u = L - 0.25;   // beyond the right edge
    if (v >= 60 && u >= 80) p.u = -0.25;     // aliases to L - 0.25
    // Cue frames shifted by 0.45 of a fringe: the orders disagree by 0.45.
    if (u >= 50 && u < 60 && frame >= 3) p.u += 0.45 * lambda;
    return p;
  };
  auto frames = render(pattern, size, 16, field, offset, modulation);
  for (int v = 0; v < size.height; ++v) {
    for (int u = 30; u < 40; ++u) frames[4].at<std::uint16_t>(v, u) = 65535;
  }

  auto expected = [&](int u, int v) {
    if (u >= 30 && u < 40) return PixelStatus::kSaturated;
    if (u >= 10 && u < 15) return PixelStatus::kLowModulation;
    if (u >= 50 && u < 60) return PixelStatus::kUnwrapInconsistent;
    if (v >= 60) return PixelStatus::kOutOfRange;
    return PixelStatus::kValid;
  };

  const ProjectorMaps maps = PhaseShift33Decoder(pattern, options).decode(frames, 16);
  int wrong_status = 0, wrong_nan = 0;
  int counts[5] = {0, 0, 0, 0, 0};
  for (int v = 0; v < size.height; ++v) {
    for (int u = 0; u < size.width; ++u) {
      const PixelStatus s = statusAt(maps, u, v);
      ++counts[static_cast<int>(s)];
      if (s != expected(u, v)) ++wrong_status;
      if (isNaN(maps.up.at<float>(v, u)) != (s != PixelStatus::kValid)) ++wrong_nan;
    }
  }
  CAPTURE(counts[0], counts[1], counts[2], counts[3], counts[4]);
  CHECK(wrong_status == 0);
  CHECK(wrong_nan == 0);
  for (int c : counts) CHECK(c > 0);

  SECTION("saturated pixels are kept when not rejected") {
    DecoderOptions keep = options;
    keep.reject_saturated = false;
    const ProjectorMaps kept = PhaseShift33Decoder(pattern, keep).decode(frames, 16);
    for (int v = 0; v < size.height; ++v) {
      for (int u = 30; u < 40; ++u) CHECK(statusAt(kept, u, v) != PixelStatus::kSaturated);
    }
  }
}

TEST_CASE("decoder scales thresholds with the bit depth", "[decoder]") {
  PhaseShift33Pattern pattern;
  const cv::Size size(64, 16);
  // 12 bits: saturation at 4095, modulation threshold 8 * 16 = 128 DN.
  const Level offset = [](int, int) { return 2000.0; };
  const Level modulation = [](int u, int) { return u < 32 ? 1000.0 : 120.0; };
  const Field field = [&](int u, int v, int) { return groundTruth(pattern, size, u, v); };
  auto frames = render(pattern, size, 12, field, offset, modulation);
  frames[2].at<std::uint16_t>(0, 0) = 4095;
  frames[2].at<std::uint16_t>(0, 1) = 4094;
  const ProjectorMaps maps = PhaseShift33Decoder(pattern, {}).decode(frames, 12);
  CHECK(statusAt(maps, 0, 0) == PixelStatus::kSaturated);
  CHECK(statusAt(maps, 1, 0) != PixelStatus::kSaturated);
  CHECK(statusAt(maps, 5, 5) == PixelStatus::kValid);
  CHECK(statusAt(maps, 40, 5) == PixelStatus::kLowModulation);
  // The same images read as 16-bit: nothing saturates, and the threshold of
  // 2048 DN rejects everything.
  const ProjectorMaps as16 = PhaseShift33Decoder(pattern, {}).decode(frames, 16);
  CHECK(statusAt(as16, 0, 0) == PixelStatus::kLowModulation);
}

TEST_CASE("kBoth is valid only where both directions are", "[decoder]") {
  PhaseShift33Pattern pattern;
  pattern.direction = Direction::kBoth;
  const cv::Size size(64, 48);
  const Level offset = [](int, int) { return 30000.0; };
  const Level modulation = [](int, int) { return 20000.0; };
  const Field field = [&](int u, int v, int) { return groundTruth(pattern, size, u, v); };
  auto frames = render(pattern, size, 16, field, offset, modulation);
  // Flatten the vertical high-frequency frames in the left half: no
  // modulation there for v_p only.
  for (int f = 6; f < 9; ++f) {
    for (int v = 0; v < size.height; ++v) {
      for (int u = 0; u < 32; ++u) frames[f].at<std::uint16_t>(v, u) = 30000;
    }
  }
  const ProjectorMaps maps = PhaseShift33Decoder(pattern, {}).decode(frames, 16);
  CHECK(statusAt(maps, 10, 10) == PixelStatus::kLowModulation);
  CHECK(isNaN(maps.up.at<float>(10, 10)));
  CHECK(isNaN(maps.vp.at<float>(10, 10)));
  CHECK(maps.modulation.at<float>(10, 10) < 1.0f);
  CHECK(statusAt(maps, 50, 10) == PixelStatus::kValid);
  CHECK_FALSE(isNaN(maps.up.at<float>(10, 50)));
  CHECK_FALSE(isNaN(maps.vp.at<float>(10, 50)));
}

TEST_CASE("decoder rejects malformed input", "[decoder]") {
  PhaseShift33Pattern pattern;
  const PhaseShift33Decoder decoder(pattern, {});
  const cv::Mat good(8, 8, CV_8UC1, cv::Scalar(100));
  std::vector<cv::Mat> frames(6);
  for (auto& f : frames) f = good.clone();
  CHECK_NOTHROW(decoder.decode(frames, 8));

  using Catch::Matchers::Contains;
  SECTION("frame count") {
    frames.pop_back();
    CHECK_THROWS_WITH(decoder.decode(frames, 8), Contains("expected 6 frames, got 5"));
  }
  SECTION("size") {
    frames[3] = cv::Mat(8, 9, CV_8UC1, cv::Scalar(1));
    CHECK_THROWS_WITH(decoder.decode(frames, 8), Contains("frame 3") && Contains("size"));
  }
  SECTION("type") {
    for (auto& f : frames) f = cv::Mat(8, 8, CV_32FC1, cv::Scalar(1));
    CHECK_THROWS_WITH(decoder.decode(frames, 8), Contains("CV_8UC1 or CV_16UC1"));
  }
  SECTION("mixed types") {
    frames[5] = cv::Mat(8, 8, CV_16UC1, cv::Scalar(1));
    CHECK_THROWS_WITH(decoder.decode(frames, 8), Contains("frame 5") && Contains("type"));
  }
  SECTION("empty") {
    for (auto& f : frames) f = cv::Mat();
    CHECK_THROWS_AS(decoder.decode(frames, 8), std::invalid_argument);
  }
  SECTION("bit depth") {
    CHECK_THROWS_WITH(decoder.decode(frames, 9), Contains("bit_depth 9"));
    CHECK_THROWS_AS(decoder.decode(frames, 0), std::invalid_argument);
  }
  SECTION("options and pattern") {
    DecoderOptions options;
    options.max_unwrap_error = 0.6f;
    CHECK_THROWS_AS(PhaseShift33Decoder(pattern, options), std::invalid_argument);
    PhaseShift33Pattern bad = pattern;
    bad.fringes = 0;
    CHECK_THROWS_AS(PhaseShift33Decoder(bad, {}), std::invalid_argument);
  }
}

TEST_CASE("derived min_modulation follows the pattern's frequency ratio", "[decoder][unwrap]") {
  PhaseShift33Pattern p40, p16;
  p40.fringes = 40;
  p16.fringes = 16;
  const float b40 = derivedMinModulation(p40, 0.3f), b16 = derivedMinModulation(p16, 0.3f);
  CHECK(b40 > b16);
  CHECK(b16 >= 8.0f);  // the floor
  CHECK(derivedMinModulation(p40, 0.35f) > b40);  // less margin left for a wrong order
  PatternSpec gray;
  gray.family = PatternFamily::kGrayCode;
  CHECK(derivedMinModulation(gray, 0.3f) == 8.0f);

  // The codec resolves the default; an explicit value stays.
  CHECK(makeCodec(p40, {})->options().min_modulation == b40);
  DecoderOptions explicit_value;
  explicit_value.min_modulation = 3.0f;
  CHECK(makeCodec(p40, explicit_value)->options().min_modulation == 3.0f);
}

TEST_CASE("at the derived min_modulation the cue keeps a 5-sigma margin", "[decoder][unwrap]") {
  // 40:1 3+3 at 16 bits (quantisation negligible) with Gaussian noise of the
  // sigma_I the derivation assumes (0.54 DN on the 8-bit scale). Just above
  // the threshold (B = 1.1 B_min) the cue's error has sigma_e = (1 -
  // max_unwrap_error) / (5 * 1.1): the share flagged inconsistent must be
  // P(|e| > max_unwrap_error) of that Gaussian, and no valid pixel may have a
  // wrong order.
  PhaseShift33Pattern pattern;
  pattern.fringes = 40;
  const DecoderOptions options;
  const float b_min = derivedMinModulation(pattern, options.max_unwrap_error);
  const double scale = 256.0;  // 8-bit DN -> 16-bit DN
  const cv::Size size(400, 250);
  const Level offset = [&](int, int) { return 25.0 * scale; };
  const Level modulation = [&](int, int) { return 1.1 * b_min * scale; };
  const Field field = [&](int u, int v, int) { return groundTruth(pattern, size, u, v); };
  auto frames = render(pattern, size, 16, field, offset, modulation);
  std::mt19937 rng(17);
  std::normal_distribution<double> noise(0.0, 0.54 * scale);
  for (cv::Mat& f : frames)
    for (int v = 0; v < size.height; ++v)
      for (int u = 0; u < size.width; ++u) {
        std::uint16_t& value = f.at<std::uint16_t>(v, u);
        value = static_cast<std::uint16_t>(std::clamp(std::round(value + noise(rng)), 0.0, 65535.0));
      }
  const ProjectorMaps maps = PhaseShift33Decoder(pattern, options).decode(frames, 16);
  const double period = pattern.wavelength(pattern.projector_width);
  int inconsistent = 0, low = 0, wrong_order = 0;
  for (int v = 0; v < size.height; ++v)
    for (int u = 0; u < size.width; ++u) {
      const PixelStatus s = statusAt(maps, u, v);
      inconsistent += s == PixelStatus::kUnwrapInconsistent;
      low += s == PixelStatus::kLowModulation;
      if (s == PixelStatus::kValid &&
          std::abs(maps.up.at<float>(v, u) - groundTruth(pattern, size, u, v).u) > period / 2)
        ++wrong_order;
    }
  const double sigma_e = (1.0 - options.max_unwrap_error) / (5.0 * 1.1);
  const double expected = std::erfc(options.max_unwrap_error / sigma_e / std::sqrt(2.0));
  const double measured = double(inconsistent) / size.area();
  CAPTURE(b_min, expected, measured, low, wrong_order);
  CHECK(measured > 0.85 * expected);
  CHECK(measured < 1.15 * expected);
  CHECK(low < size.area() / 1000);
  CHECK(wrong_order == 0);
}
