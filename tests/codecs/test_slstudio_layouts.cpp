// SLStudio's micro phase shift and modulated phase shift layouts
// (config/patterns/slstudio_micro.yaml, slstudio_modulated.yaml): sl_patterns
// renders them as SLStudio's encoders compute them (formulas written out
// here from SLStudio's CodecPhaseShiftMicro / CodecPhaseShiftModulated:
// pitches in projector px, shifts, carrier, frame order, 8-bit conversion);
// the simulator's frames of them decode with the preset to the simulator's
// ground truth, and every wrong description of the same frames is judged
// implausible (or refused for its frame count).
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

#include "sl/drivers/sim.h"
#include "sl/drivers/sim_rig.h"
#include "sl/files/pattern_config.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/decode_health.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/triangulator.h"
#include "support/sim_rig.h"

using namespace sl;
using pipeline::PatternSpec;
namespace fs = std::filesystem;

namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kCols = 1824, kRows = 1140;

PatternSpec preset(const std::string& name) {
  return files::loadPattern(std::string(SL_SOURCE_DIR) + "/config/patterns/" + name + ".yaml");
}

PatternSpec fromText(const std::string& yaml) { return files::parsePatternText(yaml, "test.yaml"); }

// SLStudio's column vector: 255 * 0.5 (1 + cos(2 pi x / pitch - phase)),
// converted to 8 bits by truncation.
double slstudioVector(int x, double pitch, double phase) {
  return std::floor(255.0 * 0.5 * (1.0 + std::cos(2.0 * kPi * x / pitch - phase)));
}

// Frame `frame` of SLStudio's micro phase shift at (row, col).
double slstudioMicro(int frame, int /*row*/, int col) {
  static const double pitches[] = {75.02, 70.00, 71.32, 72.47, 73.72,
                                   76.23, 77.35, 78.40, 79.22, 80.00};
  if (frame < 3) return slstudioVector(col, pitches[0], -2.0 * kPi / 3.0 * frame);
  const int i = frame - 2;  // 1..9
  return slstudioVector(col, pitches[i], i % 2 ? kPi : 0.0);
}

// Frame `frame` of SLStudio's modulated phase shift (24 periods, carrier of
// 16 periods over the rows) at (row, col): signal x carrier, rounded.
double slstudioModulated(int frame, int row, int col) {
  if (frame >= 9) return slstudioVector(col, kCols, 2.0 * kPi / 3.0 * (frame - 9));
  const int x = frame / 3, y = frame % 3;
  const double signal = 0.5 + 0.5 * std::cos(2.0 * kPi * col / (double(kCols) / 24) - 2.0 * kPi / 3 * x);
  const double carrier = 0.5 + 0.5 * std::cos(2.0 * kPi * row / (double(kRows) / 16) - 2.0 * kPi / 3 * y);
  return std::round(255.0 * signal * carrier);
}

drivers::SimConfig simConfig(const PatternSpec& pattern) {
  drivers::SimConfig c = test::simPlaneAndSphere();
  c.patterns = {pattern};
  return c;
}

struct Decoded {
  pipeline::DecodeHealth health;
  long valid = 0;
  double median_abs_dz_mm = 0;  // triangulated z against the simulator's depth
};

Decoded decodeAs(const drivers::SimulatedSensor& sensor, const std::vector<cv::Mat>& frames,
                 const PatternSpec& described) {
  const auto codec = pipeline::makeCodec(described, {});
  const auto maps = codec->decode(frames, 8);
  Decoded d;
  d.health = pipeline::measureDecodeHealth(described, codec->options(), maps, frames, 8);
  const auto cloud = pipeline::Triangulator(drivers::simRig(), {}).triangulate(maps);
  const cv::Mat& gt = sensor.groundTruth().depth_mm;
  std::vector<double> dz;
  for (int v = 0; v < cloud.height; ++v)
    for (int u = 0; u < cloud.width; ++u) {
      const float z = cloud.points[static_cast<std::size_t>(v) * cloud.width + u].z;
      if (!std::isfinite(z) || !std::isfinite(gt.at<float>(v, u))) continue;
      dz.push_back(std::abs(z - gt.at<float>(v, u)));
    }
  d.valid = static_cast<long>(dz.size());
  if (!dz.empty()) {
    std::nth_element(dz.begin(), dz.begin() + dz.size() / 2, dz.end());
    d.median_abs_dz_mm = dz[dz.size() / 2];
  }
  return d;
}

std::string summary(const Decoded& d) {
  return pipeline::describeDecodeHealth(d.health, "  ") + "  points " + std::to_string(d.valid) +
         ", median |dz| " + std::to_string(d.median_abs_dz_mm) + " mm";
}

}  // namespace

TEST_CASE("sl_patterns renders SLStudio's micro and modulated layouts within 1 DN",
          "[codecs][slstudio][cli]") {
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_codecs_slstudio";
  fs::remove_all(dir);
  fs::create_directories(dir);
  struct Layout {
    const char* preset;
    int frames;
    double (*formula)(int, int, int);
  };
  for (const Layout& layout : {Layout{"slstudio_micro", 12, slstudioMicro},
                               Layout{"slstudio_modulated", 12, slstudioModulated}}) {
    INFO(layout.preset);
    const fs::path out = dir / layout.preset;
    const std::string command = std::string(SL_BINARY_DIR) + "/tools/sl_patterns " +
                                SL_SOURCE_DIR + "/config/patterns/" + layout.preset +
                                ".yaml --out " + out.string() + " > " +
                                (dir / "out.txt").string() + " 2>&1";
    const int rc = std::system(command.c_str());
    REQUIRE((WIFEXITED(rc) && WEXITSTATUS(rc) == 0));
    for (int f = 0; f < layout.frames; ++f) {
      char name[32];
      std::snprintf(name, sizeof name, "pattern_%02d.png", f);
      const cv::Mat image = cv::imread((out / name).string(), cv::IMREAD_UNCHANGED);
      REQUIRE(image.type() == CV_8UC1);
      REQUIRE(image.cols == kCols);
      REQUIRE(image.rows == kRows);
      double worst = 0;
      long differ = 0;
      for (int r = 0; r < kRows; ++r)
        for (int c = 0; c < kCols; ++c) {
          const double e = std::abs(image.at<std::uint8_t>(r, c) - layout.formula(f, r, c));
          worst = std::max(worst, e);
          differ += e > 0;
        }
      INFO("frame " << f << ": " << differ << " pixels differ, by at most " << worst << " DN");
      CHECK(worst <= 1.0);
    }
    char extra[32];
    std::snprintf(extra, sizeof extra, "pattern_%02d.png", layout.frames);
    CHECK_FALSE(fs::exists(out / extra));
  }
}

TEST_CASE("SLStudio's micro and modulated layouts decode with their presets; wrong descriptions "
          "are implausible",
          "[codecs][slstudio][health]") {
  struct Wrong {
    const char* mistake;
    PatternSpec described;
  };
  struct Layout {
    PatternSpec truth;
    std::vector<Wrong> wrong;
  };
  std::vector<Layout> layouts;
  {
    Layout micro{preset("slstudio_micro"), {}};
    const std::string common =
        "name: slstudio_micro\nfamily: micro_phase_shift\ndirection: horizontal\n"
        "projector: {width: 1824, height: 1140}\n";
    const std::string right_pitches =
        "pitches_px: [75.02, 70.00, 71.32, 72.47, 73.72, 76.23, 77.35, 78.40, 79.22, 80.00]\n";
    micro.wrong.push_back({"the documented family: every further frame at shift 0",
                           fromText(common + right_pitches + "shift_sign: -1\n")});
    micro.wrong.push_back(
        {"SLStudio's older integer pitch list",
         fromText(common + "pitches_px: [74, 70, 71, 72, 73, 75, 76, 77, 78, 79]\nshift_sign: -1\n"
                  "further_phases_deg: [180, 0, 180, 0, 180, 0, 180, 0, 180]\n")});
    micro.wrong.push_back(
        {"pitches taken as periods across the projector",
         fromText(common + "frequencies: [75.02, 70.00, 71.32, 72.47, 73.72, 76.23, 77.35, 78.40, "
                           "79.22, 80.00]\nshift_sign: -1\n"
                           "further_phases_deg: [180, 0, 180, 0, 180, 0, 180, 0, 180]\n")});
    micro.wrong.push_back({"further phases the other way round (0, pi, 0, ...)",
                           fromText(common + right_pitches + "shift_sign: -1\n"
                                    "further_phases_deg: [0, 180, 0, 180, 0, 180, 0, 180, 0]\n")});
    layouts.push_back(micro);
  }
  {
    Layout modulated{preset("slstudio_modulated"), {}};
    const std::string common =
        "name: slstudio_modulated\nfamily: modulated_phase_shift\ndirection: horizontal\n"
        "projector: {width: 1824, height: 1140}\nsteps: 3\ncarrier_pitch_px: 71.25\n";
    modulated.wrong.push_back(
        {"older SLStudio's 8 periods",
         fromText(common + "frequencies: [8, 1]\nmodulated_sets: [true, false]\n")});
    modulated.wrong.push_back(
        {"16 periods", fromText(common + "frequencies: [16, 1]\nmodulated_sets: [true, false]\n")});
    modulated.wrong.push_back(
        {"the cue listed first",
         fromText(common + "frequencies: [1, 24]\nmodulated_sets: [false, true]\n")});
    layouts.push_back(modulated);
  }
  for (const Layout& layout : layouts) {
    const auto sensor = drivers::SimulatedSensor::create(simConfig(layout.truth));
    std::vector<cv::Mat> frames;
    for (int f = 0; f < layout.truth.frameCount(); ++f)
      frames.push_back(sensor->render(layout.truth.name, f, 7));
    const Decoded right = decodeAs(*sensor, frames, layout.truth);
    INFO(layout.truth.name << " right\n" << summary(right));
    WARN(layout.truth.name << " right\n" << summary(right));
    CHECK_FALSE(right.health.implausible);
    CHECK(right.valid > 500000);
    CHECK(right.median_abs_dz_mm < 0.1);
    for (const Wrong& w : layout.wrong) {
      REQUIRE(w.described.frameCount() == layout.truth.frameCount());
      const Decoded d = decodeAs(*sensor, frames, w.described);
      INFO(layout.truth.name << " described wrongly: " << w.mistake << "\n" << summary(d));
      WARN(layout.truth.name << " described wrongly: " << w.mistake << "\n" << summary(d));
      CHECK(d.health.implausible);
    }
  }
  // The modulated layout described with the family's default (every set
  // modulated) has 18 frames, not 12: refused by its frame count.
  const PatternSpec all_modulated = fromText(
      "name: slstudio_modulated\nfamily: modulated_phase_shift\ndirection: horizontal\n"
      "projector: {width: 1824, height: 1140}\nsteps: 3\nfrequencies: [24, 1]\n"
      "carrier_pitch_px: 71.25\n");
  CHECK(all_modulated.frameCount() == 18);
  CHECK(preset("slstudio_modulated").frameCount() == 12);
}

TEST_CASE("further_phases_deg and modulated_sets: checked, and kept by pattern.yml",
          "[codecs][slstudio][yaml]") {
  for (const char* name : {"slstudio_micro", "slstudio_modulated"}) {
    const PatternSpec p = preset(name);
    const PatternSpec back = files::parsePatternText(files::patternYaml(p), "pattern.yml");
    INFO(files::patternYaml(p));
    CHECK(files::patternDifferences(p, back).empty());
    CHECK(back.further_phases_rad.size() == p.further_phases_rad.size());
    CHECK(back.modulated_sets == p.modulated_sets);
  }
  const std::string micro =
      "name: m\nfamily: micro_phase_shift\ndirection: horizontal\n"
      "pitches_px: [75.02, 70.00, 71.32, 72.47, 73.72, 76.23, 77.35, 78.40, 79.22, 80.00]\n";
  CHECK_THROWS_WITH(fromText(micro + "further_phases_deg: [180, 0, 180]\n"),
                    Catch::Contains("further_phases_deg") && Catch::Contains("one shift per frequency"));
  CHECK_NOTHROW(fromText(micro + "further_phases_deg: [180, 0, 180, 0, 180, 0, 180, 0, 180]\n"));
  const std::string modulated =
      "name: m\nfamily: modulated_phase_shift\ndirection: horizontal\nfrequencies: [24, 1]\n";
  CHECK_THROWS_WITH(fromText(modulated + "modulated_sets: [true]\n"),
                    Catch::Contains("modulated_sets") && Catch::Contains("one entry per frequency"));
  CHECK_THROWS_WITH(fromText(modulated + "modulated_sets: [false, false]\n"),
                    Catch::Contains("at least one"));
  CHECK_THROWS_WITH(fromText(modulated + "modulated_sets: [yes please, false]\n"),
                    Catch::Contains("true/false"));
  CHECK_THROWS_WITH(fromText("name: p\nfamily: phase_shift\ndirection: horizontal\n"
                             "frequencies: [16, 1]\nfurther_phases_deg: [0]\n"),
                    Catch::Contains("further_phases_deg"));
}
