// A non-linear projector (gamma) compensated in decoding: the phase tables
// built from the response, the response from a grey ramp, the gamma from the
// phase-shift captures themselves.
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <string>
#include <vector>

#include <catch2/catch.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "sl/files/calibration_io.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/projector_response.h"

using namespace sl;
using pipeline::Direction;
using pipeline::PatternFamily;
using pipeline::PatternSpec;

namespace {

// A 1800 x 40 camera whose pixel column x sees projector column p(x) =
// 8 + 1.0 * x; gain and ambient vary across the image; the projector shows
// R(L) of the pattern's intensity L; 16-bit frames with optional noise.
std::vector<cv::Mat> render(const PatternSpec& spec, double gamma, double noise_dn,
                            std::uint64_t seed) {
  cv::RNG rng(seed);
  std::vector<cv::Mat> frames;
  for (int f = 0; f < spec.frameCount(); ++f) {
    cv::Mat image(40, 1800, CV_16UC1);
    for (int y = 0; y < image.rows; ++y)
      for (int x = 0; x < image.cols; ++x) {
        const double p = 8.0 + x, q = 100.0 + 20.0 * y;
        const double L = pipeline::patternIntensity(spec, f, p, q);
        const double gain = 40000.0 * (0.6 + 0.4 * std::sin(0.003 * x + 0.1 * y));
        const double ambient = 3000.0 + 10.0 * x;
        const double v = gain * std::pow(L, gamma) + ambient + rng.gaussian(noise_dn * 256.0);
        image.at<std::uint16_t>(y, x) = cv::saturate_cast<std::uint16_t>(v);
      }
    frames.push_back(image);
  }
  return frames;
}

struct Errors {
  double rms = 0, max = 0;
  double valid_fraction = 0;
};

Errors errors(const pipeline::ProjectorMaps& maps) {
  Errors e;
  double sum2 = 0;
  long n = 0, total = 0;
  for (int y = 0; y < maps.up.rows; ++y)
    for (int x = 10; x < maps.up.cols - 10; ++x) {
      ++total;
      if (maps.status.at<std::uint8_t>(y, x) != 0) continue;
      const double d = maps.up.at<float>(y, x) - (8.0 + x);
      sum2 += d * d;
      e.max = std::max(e.max, std::abs(d));
      ++n;
    }
  e.rms = std::sqrt(sum2 / std::max(n, 1L));
  e.valid_fraction = double(n) / total;
  return e;
}

PatternSpec phaseShift(int steps, std::vector<double> f) {
  PatternSpec p;
  p.name = "ps";
  p.direction = Direction::kHorizontal;
  p.steps = steps;
  p.frequencies = std::move(f);
  return p;
}

}  // namespace

TEST_CASE("a gamma 2.2 projector decodes correctly with its response", "[codecs][gamma]") {
  PatternSpec p33 = phaseShift(3, {40, 1});
  PatternSpec two = phaseShift(2, {12, 1});
  two.name = "2+1";
  two.family = PatternFamily::kTwoPlusOne;
  two.offset = 0.6;
  two.amplitude = 0.4;
  PatternSpec gps;
  gps.name = "gray_ps";
  gps.family = PatternFamily::kGrayPhaseShift;
  gps.gray_bits = 6;
  gps.steps = 3;
  gps.complementary = true;
  PatternSpec four = phaseShift(4, {64, 8, 1});
  four.name = "4step";
  four.shift_sign = -1;
  four.start_phase_rad = 0.3;
  for (const PatternSpec& spec : {p33, two, gps, four}) {
    CAPTURE(spec.name);
    const auto frames = render(spec, 2.2, 0.0, 1);
    pipeline::DecoderOptions plain;
    plain.min_modulation = 4;
    const Errors uncompensated = errors(pipeline::makeCodec(spec, plain)->decode(frames, 16));
    pipeline::DecoderOptions compensated = plain;
    compensated.projector_response = pipeline::gammaResponse(2.2);
    const Errors fixed = errors(pipeline::makeCodec(spec, compensated)->decode(frames, 16));
    WARN(spec.name << " at gamma 2.2: uncompensated RMS " << uncompensated.rms << " px ("
                   << 100 * uncompensated.valid_fraction << " % valid), compensated RMS "
                   << fixed.rms << " px, max " << fixed.max << " px ("
                   << 100 * fixed.valid_fraction << " % valid)");
    CHECK(fixed.valid_fraction > 0.99);
    CHECK(fixed.rms < 0.02);
    CHECK(fixed.max < 0.1);
    // The uncompensated error is what the table removes (4 steps cancel
    // the second harmonic: a smaller error there).
    CHECK(uncompensated.rms > 10 * fixed.rms);
  }
  // The 3+3 at gamma 2.2 without compensation: many pixels refused, and
  // period errors among the rest.
  const auto frames = render(p33, 2.2, 0.0, 1);
  pipeline::DecoderOptions plain;
  plain.min_modulation = 4;
  const Errors e = errors(pipeline::makeCodec(p33, plain)->decode(frames, 16));
  CHECK(e.valid_fraction < 0.8);
  CHECK(e.max > 20);
}

TEST_CASE("responses are checked", "[codecs][gamma]") {
  pipeline::DecoderOptions o;
  o.projector_response = {0.0f, 0.5f, 0.4f, 1.0f};
  CHECK_THROWS_WITH(pipeline::makeCodec(phaseShift(3, {16, 1}), o),
                    Catch::Contains("increase strictly"));
  o.projector_response = {0.0f};
  CHECK_THROWS_WITH(pipeline::makeCodec(phaseShift(3, {16, 1}), o), Catch::Contains("2 samples"));
  CHECK_THROWS(pipeline::gammaResponse(0.0));
  const auto r = pipeline::gammaResponse(2.2, 11);
  CHECK(r[5] == Approx(std::pow(0.5, 2.2)));
}

TEST_CASE("the gamma is estimated from the phase-shift captures themselves", "[codecs][gamma]") {
  const PatternSpec p33 = phaseShift(3, {40, 1});
  for (double gamma : {1.0, 1.8, 2.2, 2.6}) {
    CAPTURE(gamma);
    const auto frames = render(p33, gamma, 0.5, 7);
    const pipeline::GammaEstimate e = pipeline::estimateProjectorGamma(p33, frames, 16);
    WARN("gamma " << gamma << ": estimated " << e.gamma << " from " << e.pixels
                  << " pixels, residual " << e.rms_residual_periods << " periods (linear "
                  << e.rms_residual_linear_periods << ")");
    CHECK(e.gamma == Approx(gamma).margin(0.05));
    CHECK(e.rms_residual_periods <= e.rms_residual_linear_periods);
  }
  CHECK_THROWS_WITH(pipeline::estimateProjectorGamma(phaseShift(3, {1}), render(phaseShift(3, {1}), 2.2, 0, 1), 16),
                    Catch::Contains(">= 2 frequencies"));
}

TEST_CASE("the response is measured from a ramp of grey levels", "[codecs][gamma]") {
  // Flat frames at 9 levels through gamma 2.2, gain and ambient varying, noise.
  std::vector<double> levels;
  std::vector<cv::Mat> frames;
  cv::RNG rng(3);
  for (int k = 0; k <= 8; ++k) {
    const double L = k / 8.0;
    levels.push_back(L);
    cv::Mat image(60, 80, CV_8UC1);
    for (int y = 0; y < image.rows; ++y)
      for (int x = 0; x < image.cols; ++x) {
        const double gain = 150.0 + x, ambient = 10.0 + 0.2 * y;
        image.at<std::uint8_t>(y, x) =
            cv::saturate_cast<std::uint8_t>(gain * std::pow(L, 2.2) + ambient + rng.gaussian(1.0));
      }
    frames.push_back(image);
  }
  const auto response = pipeline::estimateProjectorResponse(frames, levels, 8);
  REQUIRE(response.size() == 256);
  for (int s : {64, 128, 191})
    CHECK(response[s] == Approx(std::pow(s / 255.0, 2.2)).margin(0.015));
  // Decoding with the measured response is as good as with the exact gamma.
  const PatternSpec p33 = phaseShift(3, {40, 1});
  const auto captures = render(p33, 2.2, 0.0, 1);
  pipeline::DecoderOptions o;
  o.min_modulation = 4;
  o.projector_response = response;
  const Errors e = errors(pipeline::makeCodec(p33, o)->decode(captures, 16));
  CHECK(e.valid_fraction > 0.99);
  CHECK(e.rms < 0.1);
  // Too little contrast: refused.
  std::vector<cv::Mat> dark(frames.size(), cv::Mat(60, 80, CV_8UC1, cv::Scalar(5)));
  CHECK_THROWS_WITH(pipeline::estimateProjectorResponse(dark, levels, 8),
                    Catch::Contains("enough contrast"));
}

// The command-line path: sl_patterns --ramp writes the flat frames,
// sl_calibrate --projector-response reads their camera images back into a
// response file that the decoder takes.
TEST_CASE("sl_patterns --ramp and sl_calibrate --projector-response", "[codecs][gamma][cli]") {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_codecs_ramp";
  fs::remove_all(dir);
  fs::create_directories(dir / "camera");
  const std::string bin = std::string(SL_BINARY_DIR) + "/tools/";
  const auto run = [&](const std::string& args) {
    const std::string command = bin + args + " > " + (dir / "out.txt").string() + " 2>&1";
    const int rc = std::system(command.c_str());
    std::ifstream in(dir / "out.txt");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    UNSCOPED_INFO(args << "\n" << text);
    return std::make_pair(WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, text);
  };

  REQUIRE(run("sl_patterns --ramp 8 --out " + (dir / "ramp").string()).first == 0);
  std::vector<fs::path> ramp;
  for (const auto& e : fs::directory_iterator(dir / "ramp")) ramp.push_back(e.path());
  std::sort(ramp.begin(), ramp.end());
  REQUIRE(ramp.size() == 9);
  cv::RNG rng(5);
  for (std::size_t k = 0; k < ramp.size(); ++k) {
    // Each frame flat at round(255 k / 8), at the projector's size.
    const cv::Mat frame = cv::imread(ramp[k].string(), cv::IMREAD_UNCHANGED);
    REQUIRE(frame.type() == CV_8UC1);
    CHECK(frame.size() == cv::Size(1824, 1140));
    double lo = 0, hi = 0;
    cv::minMaxLoc(frame, &lo, &hi);
    CHECK(lo == hi);
    CHECK(lo == std::round(255.0 * k / 8));
    // The camera's image of it through a gamma 2.2 projector (gain and
    // ambient varying across the image, noise), 16-bit.
    cv::Mat image(60, 80, CV_16UC1);
    for (int y = 0; y < image.rows; ++y)
      for (int x = 0; x < image.cols; ++x) {
        const double gain = 30000.0 + 200.0 * x, ambient = 2000.0 + 40.0 * y;
        image.at<std::uint16_t>(y, x) = cv::saturate_cast<std::uint16_t>(
            gain * std::pow(lo / 255.0, 2.2) + ambient + rng.gaussian(200.0));
      }
    REQUIRE(cv::imwrite((dir / "camera" / ramp[k].filename()).string(), image));
  }
  const fs::path response_file = dir / "response.yaml";
  const auto [rc, text] = run("sl_calibrate --projector-response " + (dir / "camera").string() +
                              " --out " + response_file.string());
  REQUIRE(rc == 0);
  CHECK_THAT(text, Catch::Contains("from 9 levels"));
  const std::vector<float> response = files::loadProjectorResponse(response_file.string());
  REQUIRE(response.size() >= 9);
  for (double L : {0.25, 0.5, 0.75}) {
    CAPTURE(L);
    const double at = L * (response.size() - 1);
    const std::size_t i = static_cast<std::size_t>(at);
    const double r = response[i] + (at - i) * (response[std::min(i + 1, response.size() - 1)] - response[i]);
    CHECK(r == Approx(std::pow(L, 2.2)).margin(0.015));
  }
  // The decoder takes it: a gamma 2.2 capture decodes as well as with the exact gamma.
  const PatternSpec p33 = phaseShift(3, {40, 1});
  pipeline::DecoderOptions o;
  o.min_modulation = 4;
  o.projector_response = response;
  const Errors e = errors(pipeline::makeCodec(p33, o)->decode(render(p33, 2.2, 0.0, 1), 16));
  CHECK(e.valid_fraction > 0.99);
  CHECK(e.rms < 0.1);

  // Bad input: named errors, non-zero exit codes, no file.
  const auto bad_levels = run("sl_calibrate --projector-response " + (dir / "camera").string() +
                              " --levels 0,0.5,1 --out " + (dir / "bad.yaml").string());
  CHECK(bad_levels.first != 0);
  CHECK_THAT(bad_levels.second, Catch::Contains("9 images but 3 --levels"));
  CHECK_FALSE(fs::exists(dir / "bad.yaml"));
  const auto short_ramp = run("sl_patterns --ramp 1 --out " + (dir / "ramp1").string());
  CHECK(short_ramp.first != 0);
  CHECK_THAT(short_ramp.second, Catch::Contains("--ramp N needs N in 2..255"));
}
