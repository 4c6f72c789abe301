// sl_process on real captures (slstudio-skull, read from SL_SHARED_DATA_DIR,
// see its README.md): the 2x3 phase shift and the Gray code of one skull
// pose against SLStudio's own Gray-code reconstruction.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "sl/files/calibration_io.h"
#include "sl/files/pattern_config.h"
#include "sl_process/process.h"

namespace fs = std::filesystem;
using namespace sl;

namespace {

const std::string kData = std::string(SL_SHARED_DATA_DIR) + "/slstudio-skull";

struct ReferencePoint {
  int u, v;
  double x, y, z;
};

std::vector<ReferencePoint> readReference() {
  std::ifstream in(kData + "/skull_gray/reference_points.txt");
  REQUIRE(in.good());
  std::vector<ReferencePoint> points;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    ReferencePoint p{};
    s >> p.u >> p.v >> p.x >> p.y >> p.z;
    points.push_back(p);
  }
  return points;
}

tools::ProcessResult run(const std::string& pattern_file, const std::string& folder,
                         float min_modulation) {
  const auto pattern = files::loadPattern(std::string(SL_SOURCE_DIR) + "/config/patterns/" + pattern_file);
  const auto calibration = files::loadCalibration(kData + "/calibration.xml").calibration;
  const auto frames = tools::loadFrames(tools::listImages(kData + "/" + folder));
  pipeline::DecoderOptions decoder;
  decoder.min_modulation = min_modulation;
  pipeline::TriangulatorOptions triangulator;
  triangulator.projector_distortion_iterations = 0;  // SLStudio ignores projector distortion
  // SLStudio's reference is in the undistorted image grid.
  return tools::processCapture(pattern, calibration, frames, decoder, triangulator, true);
}

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * v.size()))];
}

}  // namespace

TEST_CASE("skull_2x3 against SLStudio's Gray-code reconstruction", "[process][real]") {
  const auto reference = readReference();
  REQUIRE(reference.size() == 93876);
  // README mask: sqrt((2I1-I2-I3)^2 + 3(I2-I3)^2) = 3B > 55.
  const auto result = run("slstudio_2x3.yaml", "skull_2x3", 55.0f / 3.0f);
  const auto& cloud = result.cloud;
  std::vector<double> dz, adz;
  for (const ReferencePoint& p : reference) {
    const float z = cloud.points[static_cast<std::size_t>(p.v) * cloud.width + p.u].z;
    if (!std::isfinite(z)) continue;
    dz.push_back(z - p.z);
    adz.push_back(std::abs(z - p.z));
  }
  const double median = percentile(dz, 0.5);
  const double abs_median = percentile(adz, 0.5);
  const double abs_p95 = percentile(adz, 0.95);
  const double within_1mm =
      double(std::count_if(adz.begin(), adz.end(), [](double d) { return d <= 1.0; })) / adz.size();
  WARN("skull_2x3: " << dz.size() << " common pixels, median dz " << median << " mm, |dz| median "
                     << abs_median << " mm, p95 " << abs_p95 << " mm, " << 100 * within_1mm
                     << " % within 1 mm");
  CHECK(dz.size() >= 75000);
  CHECK(std::abs(median) <= 0.15);
  CHECK(abs_median < 0.2);
  CHECK(abs_p95 < 0.8);
  CHECK(within_1mm >= 0.97);
}

TEST_CASE("skull_gray decoded with the Gray-code codec reproduces the reference", "[process][real]") {
  const auto reference = readReference();
  const auto result = run("slstudio_gray.yaml", "skull_gray", 5.0f);
  const auto& cloud = result.cloud;
  int within = 0, decoded = 0;
  std::vector<double> dz;
  for (const ReferencePoint& p : reference) {
    const auto& q = cloud.points[static_cast<std::size_t>(p.v) * cloud.width + p.u];
    if (!std::isfinite(q.z)) continue;
    ++decoded;
    dz.push_back(q.z - p.z);
    const double d = std::sqrt((q.x - p.x) * (q.x - p.x) + (q.y - p.y) * (q.y - p.y) +
                               (q.z - p.z) * (q.z - p.z));
    within += d <= 0.5;
  }
  const double fraction = double(within) / reference.size();
  WARN("skull_gray: " << decoded << " of " << reference.size() << " reference pixels decoded, "
                      << 100 * fraction << " % within 0.5 mm, median dz " << percentile(dz, 0.5)
                      << " mm");
  CHECK(fraction >= 0.90);
}

TEST_CASE("sl_process writes maps, cloud and previews", "[process][cli]") {
  const fs::path out = fs::path(SL_BINARY_DIR) / "test_process_out";
  fs::remove_all(out);
  const std::string command = std::string(SL_BINARY_DIR) + "/tools/sl_process --pattern " +
                              SL_SOURCE_DIR + "/config/patterns/slstudio_2x3.yaml --calibration " +
                              kData + "/calibration.xml --images " + kData + "/skull_2x3 --out " +
                              out.string() + " --min-modulation 18.3 --projector-iterations 0 --undistort-images > /dev/null";
  REQUIRE(std::system(command.c_str()) == 0);
  for (const char* f : {"up.tiff", "vp.tiff", "modulation.tiff", "offset.tiff", "depth.tiff",
                        "status.png", "cloud.ply", "depth.png", "modulation.png"})
    CHECK(fs::file_size(out / f) > 0);
  // A wrong frame count is an error with exit code 1.
  const std::string bad = std::string(SL_BINARY_DIR) + "/tools/sl_process --pattern " +
                          SL_SOURCE_DIR + "/config/patterns/slstudio_2x3.yaml --calibration " +
                          kData + "/calibration.xml --images " + kData + "/skull_gray --out " +
                          out.string() + " 2>/dev/null";
  CHECK(WEXITSTATUS(std::system(bad.c_str())) == 1);
}
