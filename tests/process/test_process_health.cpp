// sl_process on a recording of the simulated sensor (issue 32): a pattern file
// that does not describe the recorded sequence gives no silent wrong cloud.
// The recording is sim.yaml's 3+3_horizontal (40 periods) as the recorder
// writes it (set 2, with its pattern.yml) and as it wrote it before sets kept
// their pattern's description (set 1); config/patterns/
// paper_3+3_horizontal.yaml has the same name and 16 periods.
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <catch2/catch.hpp>
#include <opencv2/imgcodecs.hpp>

#include "sl/files/calibration_io.h"
#include "sl/files/pattern_config.h"
#include "sl/drivers/recording.h"
#include "sl/drivers/sim.h"
#include "sl/drivers/sim_rig.h"
#include "support/sim_rig.h"

namespace fs = std::filesystem;
using namespace sl;

namespace {

struct Run {
  int exit_code;
  std::string output;  // stdout and stderr
};

Run slProcess(const std::string& args) {
  const fs::path log = fs::path(SL_BINARY_DIR) / "test_process_health.log";
  const std::string command = std::string(SL_BINARY_DIR) + "/tools/sl_process " + args + " > " +
                              log.string() + " 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream in(log);
  std::stringstream text;
  text << in.rdbuf();
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, text.str()};
}

void writeFile(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

const char* const kPattern40 =
    "name: 3+3_horizontal\nfamily: phase_shift\ndirection: horizontal\n"
    "projector: {width: 1824, height: 1140}\nsteps: 3\nfrequencies: [40, 1]\n"
    "unwrapping: unit_cue\n";

}  // namespace

TEST_CASE("sl_process: a recording checked against the pattern file, implausible decodes exit 3",
          "[process][health]") {
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_process_health";
  fs::remove_all(dir);
  fs::create_directories(dir);
  // The simulator of sim.yaml (its rig, 3+3_horizontal at 40 periods) seeing
  // a tilted plane and a sphere, 8-bit frames with its default noise.
  drivers::SimConfig sim = test::simPlaneAndSphere();
  pipeline::PatternSpec recorded;
  recorded.name = "3+3_horizontal";
  recorded.steps = 3;
  recorded.frequencies = {40, 1};
  sim.patterns = {recorded};
  const auto sensor = drivers::SimulatedSensor::create(sim);
  pipeline::ImageSet set;
  set.sequence_id = 1;
  set.pattern_name = recorded.name;
  pipeline::CameraImages camera;
  camera.camera_id = "sim_top";
  for (int f = 0; f < recorded.frameCount(); ++f) {
    camera.frames.push_back(sensor->render(recorded.name, f, 3));
    camera.stamps_ns.push_back(f);
  }
  set.cameras = {camera};
  const fs::path recording = dir / "recording";
  drivers::createRecording(recording.string(), "test");
  drivers::writeRecordedSet(recording.string(), 1, set);
  drivers::writeRecordedSet(recording.string(), 2, set, files::patternYaml(recorded));
  const std::string images = (recording / "set_000001").string();
  const std::string described = (recording / "set_000002").string();
  files::CalibrationFile calibration;
  calibration.calibration = sim.rig;
  const std::string calibration_path = (dir / "rig.yaml").string();
  files::saveCalibration(calibration, calibration_path);
  const std::string common = " --calibration " + calibration_path + " --images " + images;
  const std::string common_described =
      " --calibration " + calibration_path + " --images " + described;

  SECTION("same preset name, other period, the set's pattern.yml: refused naming both (exit 2)") {
    const std::string paper = std::string(SL_SOURCE_DIR) + "/config/patterns/paper_3+3_horizontal.yaml";
    const Run r = slProcess("--pattern " + paper + " --out " + (dir / "out16d").string() +
                            common_described);
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(r.output.find(paper) != std::string::npos);
    CHECK(r.output.find((fs::path(described) / "pattern.yml").string()) != std::string::npos);
    CHECK(r.output.find("frequencies: [40, 1] vs [16, 1]") != std::string::npos);
    CHECK(!fs::exists(dir / "out16d" / "cloud.ply"));  // refused before decoding
    // --accept-implausible does not cover a pattern file that is not the recording's.
    const Run accepted = slProcess("--pattern " + paper + " --out " + (dir / "out16d").string() +
                                   common_described + " --accept-implausible");
    CHECK(accepted.exit_code == 2);
  }
  SECTION("same preset name, other period, a set without pattern.yml: implausible (exit 3)") {
    const Run r = slProcess("--pattern " + std::string(SL_SOURCE_DIR) +
                            "/config/patterns/paper_3+3_horizontal.yaml --out " +
                            (dir / "out16").string() + common);
    INFO(r.output);
    CHECK(r.exit_code == 3);
    CHECK(r.output.find("implausible") != std::string::npos);
    CHECK(r.output.find("fail unwrapping") != std::string::npos);
    // Told to accept it: exit 0, the health still printed.
    const Run accepted = slProcess("--pattern " + std::string(SL_SOURCE_DIR) +
                                   "/config/patterns/paper_3+3_horizontal.yaml --out " +
                                   (dir / "out16").string() + common + " --accept-implausible");
    INFO(accepted.output);
    CHECK(accepted.exit_code == 0);
    CHECK(accepted.output.find("IMPLAUSIBLE") != std::string::npos);
  }
  SECTION("the right description: exit 0 and the simulator's depth") {
    writeFile(dir / "p40.yaml", kPattern40);
    const fs::path out = dir / "out40";
    // The set's own pattern.yml as the pattern file checks alike.
    const Run own = slProcess("--pattern " + (fs::path(described) / "pattern.yml").string() +
                              " --out " + (dir / "out_own").string() + common_described);
    INFO(own.output);
    CHECK(own.exit_code == 0);
    const Run r = slProcess("--pattern " + (dir / "p40.yaml").string() + " --out " +
                            out.string() + common_described);
    INFO(r.output);
    REQUIRE(r.exit_code == 0);
    CHECK(r.output.find("IMPLAUSIBLE") == std::string::npos);
    const cv::Mat depth = cv::imread((out / "depth.tiff").string(), cv::IMREAD_UNCHANGED);
    const cv::Mat& truth = sensor->groundTruth().depth_mm;
    REQUIRE(depth.size() == truth.size());
    std::vector<double> error;
    for (int v = 0; v < depth.rows; ++v)
      for (int u = 0; u < depth.cols; ++u) {
        const float z = depth.at<float>(v, u), t = truth.at<float>(v, u);
        if (std::isfinite(z) && std::isfinite(t)) error.push_back(std::abs(z - t));
      }
    REQUIRE(error.size() > 100000);
    std::sort(error.begin(), error.end());
    const double median = error[error.size() / 2], p99 = error[error.size() * 99 / 100];
    WARN("right description: " << error.size() << " points, |dz| median " << median
                               << " mm, p99 " << p99 << " mm");
    CHECK(median < 0.2);
    CHECK(p99 < 2.0);
  }
  SECTION("a pattern of another name or frame count than the recording's is an error") {
    std::string other = kPattern40;
    other.replace(other.find("3+3_horizontal"), 14, "3+3_vertical");
    writeFile(dir / "other.yaml", other);
    const Run named = slProcess("--pattern " + (dir / "other.yaml").string() + " --out " +
                                (dir / "out_other").string() + common);
    INFO(named.output);
    CHECK(named.exit_code == 2);
    CHECK(named.output.find("'3+3_horizontal'") != std::string::npos);
    CHECK(named.output.find("'3+3_vertical'") != std::string::npos);
    CHECK(named.output.find("meta.yml") != std::string::npos);
    std::string four = kPattern40;
    four.replace(four.find("steps: 3"), 8, "steps: 4");
    writeFile(dir / "four.yaml", four);
    const Run counted = slProcess("--pattern " + (dir / "four.yaml").string() + " --out " +
                                  (dir / "out_four").string() + common);
    INFO(counted.output);
    CHECK(counted.exit_code == 2);
    CHECK(counted.output.find("6 frames") != std::string::npos);
    CHECK(counted.output.find("describes 8") != std::string::npos);
  }
}

TEST_CASE("sl_process: a calibration file of other keys points to --calibration-keys",
          "[process][cli]") {
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_process_keys";
  fs::create_directories(dir);
  // An OpenCV FileStorage calibration with keys of another tool (K1, D1, ...).
  writeFile(dir / "stereo.yaml",
            "%YAML:1.0\n---\nK1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
            "   data: [ 1000., 0., 320., 0., 1000., 240., 0., 0., 1. ]\n");
  writeFile(dir / "own.yaml", "format: sl-sensor-calibration/1\ncam: {}\n");
  for (const char* file : {"stereo.yaml", "own.yaml"}) {
    const Run r = slProcess("--pattern " + std::string(SL_SOURCE_DIR) +
                            "/config/patterns/paper_3+3_horizontal.yaml --images " + dir.string() +
                            " --calibration " + (dir / file).string() + " --out " +
                            (dir / "out").string());
    INFO(r.output);
    CHECK(r.exit_code == 1);
    CHECK(r.output.find((dir / file).string()) != std::string::npos);
    CHECK(r.output.find("--calibration-keys") != std::string::npos);
  }
}

TEST_CASE("patternYaml() gives every preset back; patternDifferences() names what differs",
          "[process][health]") {
  int presets = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(SL_SOURCE_DIR) / "config/patterns")) {
    const std::string path = entry.path().string();
    pipeline::PatternSpec spec;
    try {
      spec = files::loadPattern(path);
    } catch (const std::exception&) {
      continue;  // not a pattern file (the calibration pattern of sl_calibrate, say)
    }
    ++presets;
    INFO(path << "\n" << files::patternYaml(spec));
    const pipeline::PatternSpec back = files::parsePatternText(files::patternYaml(spec), path);
    CHECK(back.name == spec.name);
    CHECK(back.frameCount() == spec.frameCount());
    CHECK(files::patternDifferences(spec, back).empty());
    CHECK(back.frequencies == spec.frequencies);
  }
  CHECK(presets >= 10);
  pipeline::PatternSpec a, b;
  b.frequencies = {40, 1};
  b.steps = 4;
  const auto d = files::patternDifferences(a, b);
  REQUIRE(d.size() == 3);
  CHECK(d[0] == "frames: 6 vs 8");
  CHECK(d[1] == "steps: 3 vs 4");
  CHECK(d[2] == "frequencies: [16, 1] vs [40, 1]");
}

TEST_CASE("sl_process --help lists every option and exits 0", "[process][cli]") {
  const Run r = slProcess("--help");
  CHECK(r.exit_code == 0);
  CHECK(r.output.find("sl_process: help") == std::string::npos);
  // Every option the parser takes (tools/sl_process/main.cpp).
  for (const char* option :
       {"--pattern", "--images", "--list", "--calibration", "--calibration-keys", "--out",
        "--phase", "--smooth-phase", "--min-modulation", "--max-unwrap-error", "--keep-saturated",
        "--undistort-images", "--projector-iterations", "--use", "--min-depth", "--max-depth",
        "--projector-gamma", "--projector-response", "--estimate-gamma", "--accept-implausible",
        "--help"}) {
    INFO(option);
    CHECK(r.output.find(std::string(" ") + option + " ") != std::string::npos);
  }
}

namespace {

// Median of the "epipolar distance" line sl_process prints, -1 without one.
double epipolarMedian(const std::string& output) {
  const auto at = output.find("epipolar distance");
  if (at == std::string::npos) return -1;
  const auto median = output.find("median ", at);
  return median == std::string::npos ? -1 : std::stod(output.substr(median + 7));
}

}  // namespace

TEST_CASE("sl_process: the epipolar check catches a scaled coordinate that unwraps consistently",
          "[process][health][epipolar]") {
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_process_epipolar";
  fs::remove_all(dir);
  fs::create_directories(dir);
  drivers::SimConfig sim = test::simPlaneAndSphere();
  const std::string projector = "projector: {width: 1824, height: 1140}\n";
  const std::string gray60 = "name: g\nfamily: gray_phase_shift\ndirection: both\n" + projector +
                             "steps: 4\npitch_px: 60\n";
  const std::string ps16 = "name: p\nfamily: phase_shift\ndirection: both\n" + projector +
                           "steps: 3\nfrequencies: [16, 1]\n";
  sim.patterns = {files::parsePatternText(gray60, "g.yaml"),
                  files::parsePatternText(ps16, "p.yaml")};
  const auto sensor = drivers::SimulatedSensor::create(sim);
  files::CalibrationFile calibration;
  calibration.calibration = sim.rig;
  const std::string calibration_path = (dir / "rig.yaml").string();
  files::saveCalibration(calibration, calibration_path);
  for (const pipeline::PatternSpec& p : sim.patterns) {
    fs::create_directories(dir / p.name);
    for (int f = 0; f < p.frameCount(); ++f) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%02d.png", f);
      REQUIRE(cv::imwrite((dir / p.name / name).string(), sensor->render(p.name, f, 5)));
    }
  }
  struct Case {
    const char* what;
    std::string images, pattern;
    int exit_code;
  };
  const std::vector<Case> cases = {
      {"Gray + phase shift at 60 px, right", "g", gray60, 0},
      {"Gray + phase shift at 60 px declared as bits: 5 (64 px)", "g",
       "name: g\nfamily: gray_phase_shift\ndirection: both\n" + projector + "steps: 4\nbits: 5\n", 3},
      {"3+3 at 16 periods, right", "p", ps16, 0},
      {"3+3 at 16 periods declared as [15, 0.9375] (same ratio)", "p",
       "name: p\nfamily: phase_shift\ndirection: both\n" + projector +
           "steps: 3\nfrequencies: [15, 0.9375]\n", 3},
  };
  for (const Case& c : cases) {
    writeFile(dir / "pattern.yaml", c.pattern);
    const Run r = slProcess("--pattern " + (dir / "pattern.yaml").string() + " --images " +
                            (dir / c.images).string() + " --calibration " + calibration_path +
                            " --out " + (dir / "out").string());
    const double median = epipolarMedian(r.output);
    INFO(c.what << "\n" << r.output);
    WARN(c.what << ": exit " << r.exit_code << ", epipolar median " << median << " px");
    CHECK(r.exit_code == c.exit_code);
    REQUIRE(median >= 0);
    if (c.exit_code == 0) {
      CHECK(median < 0.5);
    } else {
      CHECK(median > 10);
      CHECK(r.output.find("epipolar lines") != std::string::npos);
      // The code itself agreed with itself: only the geometry tells.
      CHECK(r.output.find("fail unwrapping") == std::string::npos);
    }
  }
}

TEST_CASE("sl_process: the real SLStudio calibration captures, right and scaled descriptions",
          "[process][health][epipolar][data]") {
  const fs::path data = fs::path(SL_SHARED_DATA_DIR) / "slstudio-skull";
  if (!fs::exists(data / "calibration" / "seq4")) {
    WARN("skipped: no " << data.string());
    return;
  }
  const fs::path dir = fs::path(SL_BINARY_DIR) / "test_process_epipolar_real";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string head =
      "name: c\nfamily: phase_shift\ndirection: both\nprojector: {width: 1824, height: 1140}\n"
      "steps: 3\n";
  // seq4: the right description with the largest failing fraction and
  // residual of the six (docs/decode-health.md); projector distortion
  // ignored, as SLStudio triangulates.
  const std::string common = " --images " + (data / "calibration" / "seq4").string() +
                             " --calibration " + (data / "calibration.xml").string() +
                             " --projector-iterations 0 --undistort-images --out " +
                             (dir / "out").string();
  writeFile(dir / "right.yaml", head + "frequencies: [16, 1]\n");
  const Run right = slProcess("--pattern " + (dir / "right.yaml").string() + common);
  INFO(right.output);
  CHECK(right.exit_code == 0);
  CHECK(epipolarMedian(right.output) > 0);
  CHECK(epipolarMedian(right.output) < 4);
  writeFile(dir / "scaled.yaml", head + "frequencies: [15, 0.9375]\n");
  const Run scaled = slProcess("--pattern " + (dir / "scaled.yaml").string() + common);
  INFO(scaled.output);
  CHECK(scaled.exit_code == 3);
  CHECK(epipolarMedian(scaled.output) > 20);
  CHECK(scaled.output.find("fail unwrapping") == std::string::npos);
}
