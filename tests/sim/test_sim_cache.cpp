// The simulator's signal cache (SimConfig::signal_cache_mib): images are bit
// for bit those rendered without it, for a static and a moving sensor, both
// cameras and any noise seed; the cached signals stay within the bound,
// least recently used evicted first.
#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <cstdint>
#include <numbers>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "sl/drivers/sim.h"

namespace {

using sl::drivers::SimConfig;
using sl::drivers::SimulatedSensor;

// A small rig (480 x 360 camera: a signal is 0.66 MiB, so a bound of a few
// MiB holds a few signals), projector beside the camera; a plane and a
// sphere; a second camera above the first.
SimConfig smallConfig(std::size_t cache_mib, bool moving) {
  SimConfig c;
  auto& rig = c.rig;
  rig.camera = {480, 360, 800, 800, 239.5, 179.5, {-0.08, 0.12, 0.0005, -0.0003, 0}};
  rig.projector = {1824, 1140, 2200, 2200, 911.5, 1139, {0.02, -0.01, 0, 0, 0}};
  const double deg = std::numbers::pi / 180.0;
  rig.R = (Eigen::AngleAxisd(14.5 * deg, Eigen::Vector3d::UnitX()) *
           Eigen::AngleAxisd(15 * deg, Eigen::Vector3d::UnitY()))
              .toRotationMatrix();
  rig.t = -rig.R * Eigen::Vector3d(160, 0, 0);
  sl::drivers::SimCamera second;
  second.camera_id = "sim_left";
  second.rig = rig;
  second.rig.t = rig.t + rig.R * Eigen::Vector3d(0, 40, 0);  // 40 mm above the first camera
  c.second_camera = second;
  c.scene.planes = {{{0, 0, 650}, {0.1, -0.05, -1}, 0.8}};
  c.scene.spheres = {{{20, -10, 560}, 60, 0.7}};
  sl::pipeline::PhaseShift33Pattern p;
  p.name = "3+3_vertical";
  p.direction = sl::pipeline::Direction::kVertical;
  sl::pipeline::PhaseShift33Pattern h = p;
  h.name = "3+3_horizontal";
  h.direction = sl::pipeline::Direction::kHorizontal;
  c.patterns = {p, h};
  if (moving) c.motion.velocity_mm_s = {60, 0, 0};
  c.signal_cache_mib = cache_mib;
  return c;
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

// Renders every (camera, pattern frame) `rounds` times, each with its own
// noise seed, in the order a live run would (frames of a sequence, both
// cameras per frame).
std::vector<cv::Mat> renderAll(const SimulatedSensor& s, const std::string& pattern, int rounds) {
  std::vector<cv::Mat> images;
  std::uint64_t seed = 100;
  for (int r = 0; r < rounds; ++r)
    for (int frame = 0; frame < 6; ++frame)
      for (int camera = 0; camera < 2; ++camera)
        images.push_back(s.render(camera, pattern, frame, ++seed));
  return images;
}

void requireIdentical(const std::vector<cv::Mat>& a, const std::vector<cv::Mat>& b) {
  REQUIRE(a.size() == b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    INFO("image " << i);
    CHECK(identical(a[i], b[i]));
  }
}

}  // namespace

TEST_CASE("signal cache: the same images with and without it", "[sim][cache]") {
  const bool moving = GENERATE(false, true);
  INFO((moving ? "moving" : "static") << " sensor");
  const auto uncached = SimulatedSensor::create(smallConfig(0, moving));
  const auto cached = SimulatedSensor::create(smallConfig(256, moving));

  // Two rounds: the second is served from the cache, with new noise seeds.
  const std::vector<cv::Mat> want = renderAll(*uncached, "3+3_vertical", 2);
  const std::vector<cv::Mat> got = renderAll(*cached, "3+3_vertical", 2);
  requireIdentical(got, want);
  // Distinct seeds give distinct noise (the cache keeps the signal, not the image).
  CHECK_FALSE(identical(got[0], got[12]));

  const sl::drivers::SimSignalCacheStats off = uncached->signalCacheStats();
  CHECK(off.hits == 0);
  CHECK(off.misses == 0);
  CHECK(off.entries == 0);
  CHECK(off.uncached == want.size());
  CHECK(off.capacity_bytes == 0);

  const sl::drivers::SimSignalCacheStats on = cached->signalCacheStats();
  CHECK(on.misses == 12);  // 2 cameras x 6 (pose, projector frame)
  CHECK(on.hits == 12);
  CHECK(on.evictions == 0);
  CHECK(on.uncached == 0);
  CHECK(on.entries == 12);
  CHECK(on.bytes == 12 * std::size_t{480 * 360 * 4});

  // A sensor moved elsewhere (setMotion) renders new poses, not the cached ones.
  Eigen::Isometry3d base = Eigen::Isometry3d::Identity();
  base.translation() = Eigen::Vector3d(15, -5, 0);
  sl::drivers::SimMotion motion;
  motion.velocity_mm_s = {0, 30, 0};
  uncached->setMotion(base, motion);
  cached->setMotion(base, motion);
  requireIdentical(renderAll(*cached, "3+3_horizontal", 1),
                   renderAll(*uncached, "3+3_horizontal", 1));
  CHECK_FALSE(identical(cached->render(0, "3+3_vertical", 2, 105), got[4]));  // seed 105 as got[4]
  CHECK(identical(cached->render(0, "3+3_vertical", 2, 7), uncached->render(0, "3+3_vertical", 2, 7)));
}

TEST_CASE("signal cache: bounded, least recently used evicted first", "[sim][cache]") {
  // 2 MiB hold 3 signals of 480 x 360 floats (0.66 MiB each).
  const std::size_t signal_bytes = 480 * 360 * 4;
  const auto uncached = SimulatedSensor::create(smallConfig(0, true));
  const auto cached = SimulatedSensor::create(smallConfig(2, true));
  REQUIRE(cached->signalCacheStats().capacity_bytes == std::size_t{2} << 20);

  // Camera 0 only: frames 0, 1, 2 fill the cache; 0 again is a hit and
  // becomes the most recent, so frame 3 evicts frame 1 (the least recent).
  auto render = [&](const SimulatedSensor& s, int frame, std::uint64_t seed) {
    return s.render(0, "3+3_vertical", frame, seed);
  };
  for (int frame : {0, 1, 2}) CHECK(identical(render(*cached, frame, 5), render(*uncached, frame, 5)));
  CHECK(identical(render(*cached, 0, 6), render(*uncached, 0, 6)));
  CHECK(cached->signalCacheStats().hits == 1);
  CHECK(identical(render(*cached, 3, 7), render(*uncached, 3, 7)));
  sl::drivers::SimSignalCacheStats s = cached->signalCacheStats();
  CHECK(s.evictions == 1);
  CHECK(s.entries == 3);
  CHECK(s.bytes == 3 * signal_bytes);
  CHECK(s.bytes <= s.capacity_bytes);
  CHECK(identical(render(*cached, 0, 8), render(*uncached, 0, 8)));  // still cached
  CHECK(cached->signalCacheStats().hits == 2);
  CHECK(identical(render(*cached, 1, 9), render(*uncached, 1, 9)));  // was evicted: a miss
  s = cached->signalCacheStats();
  CHECK(s.hits == 2);
  CHECK(s.misses == 5);
  CHECK(s.evictions == 2);

  // Both cameras cycling through 6 frames: every access misses, the bound holds.
  const std::vector<cv::Mat> want = renderAll(*uncached, "3+3_vertical", 2);
  const std::vector<cv::Mat> got = renderAll(*cached, "3+3_vertical", 2);
  requireIdentical(got, want);
  s = cached->signalCacheStats();
  CHECK(s.entries == 3);
  CHECK(s.bytes <= s.capacity_bytes);
  CHECK(s.misses + s.hits == 7 + 24);
  CHECK(s.evictions == s.misses - 3);
  CHECK(s.uncached == 0);
}

TEST_CASE("signal cache: a bound below one signal caches nothing", "[sim][cache]") {
  SimConfig config = smallConfig(0, true);
  config.rig.camera = {1440, 1080, 2400, 2400, 719.5, 539.5, {}};  // 5.9 MiB per signal
  config.second_camera.reset();
  config.signal_cache_mib = 4;
  const auto sensor = SimulatedSensor::create(config);
  const cv::Mat a = sensor->render(0, "3+3_vertical", 1, 3);
  config.signal_cache_mib = 0;
  CHECK(identical(a, SimulatedSensor::create(config)->render(0, "3+3_vertical", 1, 3)));
  const sl::drivers::SimSignalCacheStats s = sensor->signalCacheStats();
  CHECK(s.uncached == 1);
  CHECK(s.entries == 0);
  CHECK(s.misses == 0);
}
