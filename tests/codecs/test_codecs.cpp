// Pattern codecs: every family round-trips through the simulated sensor
// (generate -> render -> decode, compared with the simulator's ground-truth
// projector coordinates), analytic renders, pattern files and their errors,
// the LightCrafter 4500 image forms.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <catch2/catch.hpp>

#include "sl/daemon/config.h"
#include "sl/files/pattern_config.h"
#include "sl/drivers/sim.h"
#include "sl/drivers/sim_rig.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/projector_images.h"
#include "support/sim_rig.h"

using namespace sl;
using pipeline::Direction;
using pipeline::PatternFamily;
using pipeline::PatternSpec;

namespace {

// The rig of config/sim.yaml (drivers::simRig()).
drivers::SimConfig simConfig(std::vector<PatternSpec> patterns) {
  drivers::SimConfig c = test::simPlaneAndSphere();
  // The round trip is measured without noise and with pinhole optics: defocus
  // blur (the simulator's default lenses) is a separate effect.
  c.gain_dn_per_electron = 0;
  c.read_noise_dn = 0;
  c.camera_lens.f_number = 0;
  c.projector_lens.f_number = 0;
  c.bit_depth = 16;
  c.patterns = std::move(patterns);
  return c;
}

PatternSpec phaseShift(const std::string& name, Direction d, int steps, std::vector<double> f,
                       pipeline::Unwrapping u = pipeline::Unwrapping::kHierarchical) {
  PatternSpec p;
  p.name = name;
  p.direction = d;
  p.steps = steps;
  p.frequencies = std::move(f);
  p.unwrapping = u;
  return p;
}

PatternSpec gray(const std::string& name, Direction d, int bits, bool inverse, bool references) {
  PatternSpec p;
  p.name = name;
  p.family = PatternFamily::kGrayCode;
  p.direction = d;
  p.gray_bits = bits;
  p.gray_inverse = inverse;
  p.reference_frames = references;
  return p;
}

std::vector<PatternSpec> allFamilies() {
  std::vector<PatternSpec> v;
  v.push_back(phaseShift("3+3_horizontal", Direction::kHorizontal, 3, {16, 1}));
  v.push_back(phaseShift("3+3_both", Direction::kBoth, 3, {16, 1}));
  v.push_back(phaseShift("12step_4freq", Direction::kHorizontal, 12, {64, 16, 4, 1}));
  v.push_back(phaseShift("heterodyne", Direction::kVertical, 4, {70, 64, 59},
                         pipeline::Unwrapping::kHeterodyne));
  PatternSpec shifted = phaseShift("4step_sign_start_order", Direction::kHorizontal, 4, {1, 20});
  shifted.shift_sign = -1;
  shifted.start_phase_rad = std::numbers::pi / 2;
  shifted.offset = 0.6;
  shifted.amplitude = 0.4;
  shifted.frame_order = {7, 6, 5, 4, 0, 1, 2, 3};
  v.push_back(shifted);
  PatternSpec two = phaseShift("2+1_both", Direction::kBoth, 2, {12, 1});
  two.family = PatternFamily::kTwoPlusOne;
  two.offset = 0.6;
  two.amplitude = 0.4;
  v.push_back(two);
  v.push_back(gray("gray_full_inverse", Direction::kHorizontal, 0, true, false));
  v.push_back(gray("gray_10_references", Direction::kBoth, 10, false, true));
  PatternSpec gps = gray("gray_ps_complementary", Direction::kHorizontal, 5, false, true);
  gps.family = PatternFamily::kGrayPhaseShift;
  gps.complementary = true;
  gps.steps = 4;
  v.push_back(gps);
  PatternSpec gps_plain = gray("gray_ps_plain", Direction::kVertical, 5, true, false);
  gps_plain.family = PatternFamily::kGrayPhaseShift;
  gps_plain.steps = 3;
  v.push_back(gps_plain);
  // Gray + phase shift thresholded against the fringe mean (no references,
  // no inverses), with and without the complementary bit.
  PatternSpec gps_mean = gray("gray_ps_mean_complementary", Direction::kHorizontal, 6, false, false);
  gps_mean.family = PatternFamily::kGrayPhaseShift;
  gps_mean.complementary = true;
  gps_mean.steps = 4;
  v.push_back(gps_mean);
  PatternSpec gps_mean_plain = gray("gray_ps_mean_plain", Direction::kBoth, 5, false, false);
  gps_mean_plain.family = PatternFamily::kGrayPhaseShift;
  gps_mean_plain.steps = 3;
  v.push_back(gps_mean_plain);
  // A 60 px fringe pitch (30.4 periods) with a unit cue, captured with a
  // white and a black frame that are not part of the code in between.
  PatternSpec pitch = phaseShift("pitch60_skipped_frames", Direction::kHorizontal, 3, {1824.0 / 60, 1});
  pitch.frame_order = {0, 1, 2, pipeline::kSkippedFrame, pipeline::kSkippedFrame, 3, 4, 5};
  v.push_back(pitch);
  // Micro phase shifting: six pitches between 16 and 18.5 px, no unit cue.
  PatternSpec micro = phaseShift("micro_6", Direction::kHorizontal, 3, {});
  micro.family = PatternFamily::kMicroPhaseShift;
  for (double pitch_px : {16.0, 16.5, 17.0, 17.5, 18.0, 18.5}) micro.frequencies.push_back(1824.0 / pitch_px);
  v.push_back(micro);
  // Modulated phase shifting: the 3+3 sets, each frame at 3 carrier shifts
  // of a 9 px carrier along the rows.
  PatternSpec modulated = phaseShift("modulated_3x3", Direction::kHorizontal, 3, {16, 1});
  modulated.family = PatternFamily::kModulatedPhaseShift;
  modulated.carrier_pitch_px = 9;
  v.push_back(modulated);
  return v;
}

struct Errors {
  double rms = 0, max = 0;
  long count = 0, lit = 0;
  long within_half_stripe = 0;
};

void accumulate(const cv::Mat& decoded, const cv::Mat& truth, const cv::Mat& status,
                double half_stripe, Errors& e, double& sum2) {
  for (int v = 0; v < truth.rows; ++v) {
    for (int u = 0; u < truth.cols; ++u) {
      const float t = truth.at<float>(v, u);
      // Ground truth lit, away from the projector's edges.
      if (!std::isfinite(t) || t < 2 || t > 1820) continue;
      ++e.lit;
      if (status.at<std::uint8_t>(v, u) != 0) continue;
      const double d = decoded.at<float>(v, u) - t;
      ++e.count;
      sum2 += d * d;
      e.max = std::max(e.max, std::abs(d));
      e.within_half_stripe += std::abs(d) <= half_stripe + 0.1;
    }
  }
}

}  // namespace

TEST_CASE("every family round-trips through the simulated sensor", "[codecs][sim]") {
  const auto patterns = allFamilies();
  const auto sensor = drivers::SimulatedSensor::create(simConfig(patterns));
  const auto& gt = sensor->groundTruth();
  pipeline::DecoderOptions options;
  options.min_modulation = 4;
  for (const PatternSpec& p : patterns) {
    const auto codec = pipeline::makeCodec(p, options);
    std::vector<cv::Mat> frames;
    for (int f = 0; f < codec->frameCount(); ++f) frames.push_back(sensor->render(p.name, f, 1));
    const pipeline::ProjectorMaps maps = codec->decode(frames, 16);
    const bool gray_only = p.family == PatternFamily::kGrayCode;
    Errors e;
    double sum2 = 0;
    if (p.direction != Direction::kVertical)
      accumulate(maps.up, gt.up, maps.status, gray_only ? p.stripeWidth(1824) / 2 : 0, e, sum2);
    if (p.direction != Direction::kHorizontal) {
      Errors ev;
      double sum2v = 0;
      accumulate(maps.vp, gt.vp, maps.status, gray_only ? p.stripeWidth(1140) / 2 : 0, ev, sum2v);
      e.count += ev.count;
      e.lit += ev.lit;
      e.max = std::max(e.max, ev.max);
      e.within_half_stripe += ev.within_half_stripe;
      sum2 += sum2v;
    }
    e.rms = std::sqrt(sum2 / std::max<long>(e.count, 1));
    const double decoded_fraction = double(e.count) / e.lit;
    WARN(p.name << " (" << pipeline::toString(p.family) << ", " << codec->frameCount()
                << " frames): RMS " << e.rms << " px, max " << e.max << " px, "
                << 100 * decoded_fraction << " % of lit pixels decoded");
    CHECK(decoded_fraction > 0.97);
    if (gray_only) {
      // Gray code quantises to the stripe: the error is uniform within
      // +-stripe/2, RMS stripe/sqrt(12) (0.29 px at 1 px stripes).
      const double stripe = p.stripeWidth(1824);
      CHECK(double(e.within_half_stripe) / e.count > 0.998);
      CHECK(e.rms < stripe / std::sqrt(12.0) + 0.05);
    } else if (p.family == PatternFamily::kGrayPhaseShift && !p.complementary) {
      // Plain Gray + phase shift has the classic edge errors: a pixel at a
      // stripe boundary may take the neighbour's fringe order (one period
      // off). Rare without blur; the complementary bit removes them.
      CHECK(double(e.within_half_stripe) / e.count > 0.9999);
    } else {
      CHECK(e.rms < 0.05);
    }
  }
}

TEST_CASE("phase-shift codecs decode analytic 16-bit renders to 1e-2 px", "[codecs]") {
  // Continuous patterns (no 8-bit projector quantisation), a linear map
  // camera pixel -> projector coordinate.
  auto patterns = allFamilies();
  const cv::Size size(400, 60);
  for (const PatternSpec& p : patterns) {
    if (p.family == PatternFamily::kGrayCode) continue;
    const auto codec = pipeline::makeCodec(p, {});
    std::vector<cv::Mat> frames;
    auto u_of = [](int x, int y) { return 3.0 + x * 4.5 + 0.013 * y; };
    auto v_of = [](int x, int y) { return 2.0 + y * 18.7 + 0.37 * x; };
    for (int f = 0; f < codec->frameCount(); ++f) {
      cv::Mat image(size, CV_16UC1);
      for (int y = 0; y < size.height; ++y)
        for (int x = 0; x < size.width; ++x)
          image.at<std::uint16_t>(y, x) = static_cast<std::uint16_t>(
              std::lround(3000 + 50000 * pipeline::patternIntensity(p, f, u_of(x, y), v_of(x, y))));
      frames.push_back(image);
    }
    const auto maps = codec->decode(frames, 16);
    double max_error = 0;
    int valid = 0, off = 0;
    for (int y = 0; y < size.height; ++y) {
      for (int x = 0; x < size.width; ++x) {
        const double u = u_of(x, y), v = v_of(x, y);
        if (u > 1820 || v > 1136) continue;
        if (maps.status.at<std::uint8_t>(y, x) != 0) continue;
        ++valid;
        double error = 0;
        if (p.direction != Direction::kVertical) error = std::abs(maps.up.at<float>(y, x) - u);
        if (p.direction != Direction::kHorizontal)
          error = std::max(error, double(std::abs(maps.vp.at<float>(y, x) - v)));
        // Plain Gray + phase shift: edge errors (see the simulator test).
        if (error > 1.0 && p.family == PatternFamily::kGrayPhaseShift && !p.complementary) {
          ++off;
          continue;
        }
        max_error = std::max(max_error, error);
      }
    }
    CAPTURE(p.name, valid, max_error, off);
    CHECK(valid > 10000);
    CHECK(off < valid / 1000);
    CHECK(max_error < 1e-2);
  }
}

TEST_CASE("decodeRows over row blocks equals decode", "[codecs]") {
  const auto patterns = allFamilies();
  const auto sensor = drivers::SimulatedSensor::create(simConfig({patterns[1]}));
  const auto codec = pipeline::makeCodec(patterns[1], {});
  std::vector<cv::Mat> frames;
  for (int f = 0; f < codec->frameCount(); ++f) frames.push_back(sensor->render(patterns[1].name, f, 3));
  const auto whole = codec->decode(frames, 16);
  pipeline::ProjectorMaps blocks;
  codec->prepare(frames, 16, blocks);
  for (int y = 0; y < 1080; y += 77) codec->decodeRows(frames, 16, y, std::min(y + 77, 1080), blocks);
  CHECK(cv::norm(whole.status, blocks.status, cv::NORM_INF) == 0);
  CHECK(cv::norm(whole.modulation, blocks.modulation, cv::NORM_INF) == 0);
  cv::Mat a = whole.up.clone(), b = blocks.up.clone();
  cv::patchNaNs(a, -1);
  cv::patchNaNs(b, -1);
  CHECK(cv::norm(a, b, cv::NORM_INF) == 0);
}

TEST_CASE("every preset in config/patterns loads and validates", "[codecs][yaml]") {
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(std::string(SL_SOURCE_DIR) + "/config/patterns")) {
    const PatternSpec p = files::loadPattern(entry.path().string());
    CAPTURE(entry.path().string());
    CHECK_NOTHROW(pipeline::makeCodec(p, {}));
    CHECK(p.projector_width == 1824);
    ++count;
  }
  CHECK(count >= 10);
  const PatternSpec gray_preset =
      files::loadPattern(std::string(SL_SOURCE_DIR) + "/config/patterns/slstudio_gray.yaml");
  CHECK(gray_preset.frameCount() == 12);
  const PatternSpec twoone =
      files::loadPattern(std::string(SL_SOURCE_DIR) + "/config/patterns/sl_sensor_scan_2+1.yaml");
  CHECK(twoone.frameCount() == 5);
}

TEST_CASE("pattern file errors name the file, line and key", "[codecs][yaml]") {
  struct Case {
    std::string text, message;
  };
  const auto c = GENERATE(
      Case{"family: phase_shift\ndirection: horizontal\nfrequencies: [16, 1]\nstepz: 3\n",
           "p.yaml:4: unknown key 'stepz'"},
      Case{"family: phase_shift\ndirection: horizontal\nfrequencies: [16, 2]\n", "key 'frequencies'"},
      Case{"family: phase_shift\ndirection: horizontal\nfrequencies: [70, 64, 58]\nunwrapping: heterodyne\n",
           "key 'frequencies'"},
      Case{"family: gray_code\ndirection: horizontal\nbits: 12\n", "key 'bits'"},
      Case{"family: gray_phase_shift\ndirection: horizontal\nbits: 5\npitch_px: 60\n",
           "key 'pitch_px'"},
      Case{"family: gray_phase_shift\ndirection: horizontal\npitch_px: 3\n", "key 'pitch_px'"},
      Case{"family: gray_code\ndirection: horizontal\npitch_px: 1\n", "key 'pitch_px'"},
      Case{"family: gray_code\ndirection: horizontal\npitch_px: 4000\n", "key 'pitch_px'"},
      Case{"family: gray_code\ndirection: horizontal\nfrequencies: [1]\n", "unknown key 'frequencies'"},
      Case{"family: hexagons\ndirection: horizontal\n", "key 'family': unknown pattern family 'hexagons'"},
      Case{"family: phase_shift\ndirection: horizontal\nfrequencies: [16, 1]\nframe_order: [0, 1, 2, 3, 4, 4]\n",
           "key 'frame_order'"},
      Case{"family: two_plus_one\ndirection: both\nfrequencies: [12, 1]\namplitude: 0.7\n", "key 'amplitude'"});
  std::string message;
  try {
    files::parsePatternText(c.text, "p.yaml");
  } catch (const files::ConfigError& e) {
    message = e.what();
  }
  CAPTURE(c.text, message);
  CHECK(message.find(c.message) != std::string::npos);
  CHECK(message.rfind("p.yaml", 0) == 0);
}

TEST_CASE("the daemon config accepts every family and pattern files", "[codecs][yaml]") {
  std::ifstream in(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string anchor = "patterns:\n";
  const auto at = text.find(anchor);
  REQUIRE(at != std::string::npos);
  text.insert(at + anchor.size(),
              "  - {name: gps, family: gray_phase_shift, direction: both, bits: 4, steps: 4, complementary: true}\n"
              "  - {name: het, family: phase_shift, direction: horizontal, steps: 4, frequencies: [70, 64, 59], unwrapping: heterodyne}\n"
              "  - {name: preset, file: " + std::string(SL_SOURCE_DIR) + "/config/patterns/sl_sensor_scan_2+1.yaml}\n");
  const daemon::DaemonConfig config = daemon::parseConfig(text, "test.yaml");
  REQUIRE(config.findPattern("gps") != nullptr);
  CHECK(config.findPattern("gps")->family == PatternFamily::kGrayPhaseShift);
  CHECK(config.findPattern("het")->unwrapping == pipeline::Unwrapping::kHeterodyne);
  CHECK(config.findPattern("preset")->family == PatternFamily::kTwoPlusOne);
  CHECK(config.sim.patterns.size() == config.patterns.size());
}

TEST_CASE("LightCrafter 4500 forms: diamond downsampling and 24-bit packing", "[codecs][lightcrafter]") {
  PatternSpec p = phaseShift("3+3", Direction::kHorizontal, 3, {16, 1});
  const auto images = pipeline::generatePatternImages(p);
  REQUIRE(images.size() == 6);
  std::vector<cv::Mat> native;
  for (const auto& image : images) native.push_back(pipeline::diamondDownsample(image));
  CHECK(native[0].cols == 912);
  CHECK(native[0].rows == 1140);
  // Mirror (r, c) shows addressed column 2c + (r mod 2).
  CHECK(native[1].at<std::uint8_t>(4, 100) == images[1].at<std::uint8_t>(4, 200));
  CHECK(native[1].at<std::uint8_t>(5, 100) == images[1].at<std::uint8_t>(5, 201));
  const auto packed = pipeline::packRgb24(native);
  REQUIRE(packed.size() == 2);
  const cv::Vec3b px = packed[0].at<cv::Vec3b>(7, 333);  // B, G, R
  CHECK(px[1] == native[0].at<std::uint8_t>(7, 333));   // pattern 0 -> green
  CHECK(px[2] == native[1].at<std::uint8_t>(7, 333));   // pattern 1 -> red
  CHECK(px[0] == native[2].at<std::uint8_t>(7, 333));   // pattern 2 -> blue
  // Pre-distortion with a distortion-free projector is the identity.
  pipeline::PinholeModel ideal{1824, 1140, 2200, 2200, 911.5, 569.5, {0, 0, 0, 0, 0}};
  CHECK(cv::norm(pipeline::predistort(images[0], ideal), images[0], cv::NORM_INF) <= 1);
}

TEST_CASE("8-bit 3+3 decoding (table or computed) agrees with the 16-bit kernel", "[codecs]") {
  // On CPUs without AVX2 the 8-bit 3+3 path reads phase and B^2 from a table
  // over the frame differences (with AVX2 it computes them, as for 16 bit);
  // the same frames as 16-bit images with bit_depth 8 take the computed path
  // (fast atan2). Fringe contrast falls to 0 down the image, so the
  // modulation threshold is crossed, and a band is saturated.
  const auto patterns = allFamilies();
  for (int i : {0, 1}) {
    const PatternSpec& p = patterns[i];
    REQUIRE(p.family == PatternFamily::kPhaseShift);
    REQUIRE(p.steps == 3);
    const auto codec = pipeline::makeCodec(p, {});
    const cv::Size size(600, 200);
    std::vector<cv::Mat> frames8, frames16;
    for (int f = 0; f < codec->frameCount(); ++f) {
      cv::Mat image(size, CV_8UC1);
      for (int y = 0; y < size.height; ++y) {
        const double amplitude = 230.0 * (size.height - 1 - y) / (size.height - 1);
        for (int x = 0; x < size.width; ++x) {
          const double u = 1.0 + 3.03 * x + 0.11 * y, v = 1.0 + 5.6 * y + 0.2 * x;
          const double value = 12 + amplitude * pipeline::patternIntensity(p, f, u, v);
          image.at<std::uint8_t>(y, x) = x >= 580 ? 255 : std::uint8_t(std::lround(value));
        }
      }
      frames8.push_back(image);
      cv::Mat wide;
      image.convertTo(wide, CV_16UC1);
      frames16.push_back(wide);
    }
    const auto table = codec->decode(frames8, 8);
    const auto computed = codec->decode(frames16, 8);
    int status_differs = 0, valid = 0, low = 0, saturated = 0;
    double max_coord = 0, max_modulation = 0;
    for (int y = 0; y < size.height; ++y) {
      for (int x = 0; x < size.width; ++x) {
        const int s = table.status.at<std::uint8_t>(y, x);
        if (s != computed.status.at<std::uint8_t>(y, x)) {
          ++status_differs;
          continue;
        }
        low += s == 1;
        saturated += s == 2;
        const float b = computed.modulation.at<float>(y, x);
        max_modulation = std::max(
            max_modulation, double(std::abs(table.modulation.at<float>(y, x) - b)) / std::max(b, 1.0f));
        if (s != 0) continue;
        ++valid;
        for (const cv::Mat* m : {&table.up, &table.vp}) {
          const cv::Mat& other = m == &table.up ? computed.up : computed.vp;
          if (p.direction == Direction::kHorizontal && m == &table.vp) continue;
          max_coord = std::max(max_coord, double(std::abs(m->at<float>(y, x) - other.at<float>(y, x))));
        }
      }
    }
    CAPTURE(p.name, status_differs, valid, low, saturated, max_coord, max_modulation);
    CHECK(cv::norm(table.offset, computed.offset, cv::NORM_INF) == 0);
    CHECK(valid > 40000);
    CHECK(low > 5000);
    CHECK(saturated >= 20 * size.height);
    // Threshold ties may flip a handful of pixels; the coordinates differ by
    // the fast atan2's error (1e-6 rad, ~1e-4 px here).
    CHECK(status_differs <= 10);
    CHECK(max_coord < 1e-3);
    CHECK(max_modulation < 1e-5);
  }
}
