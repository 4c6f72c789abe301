// Cost of the simulated sensor: one render() of a 1440x1080 camera frame (the
// live camera does one per frame, 30 per second) and the once-per-scene ray
// casting. Run a Release build: ./bench_sim
#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <vector>

#include "sl/drivers/sim.h"
#include "support/icosphere.h"
#include "support/relief.h"

namespace {

// optics: 0 pinhole camera and projector, 1 default defocus (both lenses at
// f/4 focused at 550 mm), 2 projector defocus only, 3 camera defocus only.
sl::drivers::SimConfig benchConfig(int bit_depth, bool noise, int optics = 1) {
  sl::drivers::SimConfig c;
  auto& rig = c.rig;
  rig.camera = {1440, 1080, 2400, 2400, 719.5, 539.5, {-0.08, 0.12, 0.0005, -0.0003, 0}};
  rig.projector = {1824, 1140, 2200, 2200, 911.5, 1139, {0.02, -0.01, 0, 0, 0}};
  const double deg = std::numbers::pi / 180.0;
  rig.R = (Eigen::AngleAxisd(14.5 * deg, Eigen::Vector3d::UnitX()) *
           Eigen::AngleAxisd(15 * deg, Eigen::Vector3d::UnitY()))
              .toRotationMatrix();
  rig.t = -rig.R * Eigen::Vector3d(160, 0, 0);
  c.scene.planes = {{{0, 0, 700}, {0.1, -0.05, -1}, 0.8}};
  c.scene.spheres = {{{20, -10, 520}, 90, 0.7}};
  sl::pipeline::PhaseShift33Pattern p;
  p.name = "3+3_both";
  p.direction = sl::pipeline::Direction::kBoth;
  c.patterns = {p};
  c.bit_depth = bit_depth;
  if (optics == 0 || optics == 3) c.projector_lens.f_number = 0;
  if (optics == 0 || optics == 2) c.camera_lens.f_number = 0;
  if (!noise) {
    c.gain_dn_per_electron = 0;
    c.read_noise_dn = 0;
  }
  return c;
}

// Renders the 12 frames of "3+3_both" in turn, a new noise seed each time.
void renderFrames(benchmark::State& state, sl::drivers::SimulatedSensor& sensor) {
  std::uint64_t seed = 0;
  int frame = 0;
  for (auto _ : state) {
    cv::Mat image = sensor.render("3+3_both", frame, ++seed);
    benchmark::DoNotOptimize(image.data);
    frame = (frame + 1) % 12;
  }
}

// Args: bit depth, noise on (1) / off (0), optics (see benchConfig).
void BM_Render(benchmark::State& state) {
  const auto sensor = sl::drivers::SimulatedSensor::create(
      benchConfig(int(state.range(0)), state.range(1) != 0, int(state.range(2))));
  renderFrames(state, *sensor);
  state.SetItemsProcessed(state.iterations() * 1440 * 1080);
}
BENCHMARK(BM_Render)
    ->Args({8, 1, 1})
    ->Args({12, 1, 1})
    ->Args({8, 0, 1})
    ->Args({8, 1, 0})
    ->Args({8, 1, 2})
    ->Args({8, 1, 3})
    ->Unit(benchmark::kMillisecond);

// A moving sensor (60 mm/s sideways, 2 mm per image): each image is seen
// from its own pose. Args: optics (see benchConfig; 0 pinhole, 1 default
// defocus), signal cache MiB (0: every image ray-casts its pose; 256, the
// default: the 12 (pose, frame) signals are cast once, then each image
// costs its noise, as in a live run whose sequences repeat their poses).
void BM_RenderMoving(benchmark::State& state) {
  sl::drivers::SimConfig config = benchConfig(8, true, int(state.range(0)));
  config.motion.velocity_mm_s = {60, 0, 0};  // 2 mm per image at 30 fps
  config.signal_cache_mib = static_cast<std::size_t>(state.range(1));
  const auto sensor = sl::drivers::SimulatedSensor::create(config);
  renderFrames(state, *sensor);
  const sl::drivers::SimSignalCacheStats cache = sensor->signalCacheStats();
  state.counters["cache_hits"] = double(cache.hits);
  state.counters["cache_misses"] = double(cache.misses);
}
BENCHMARK(BM_RenderMoving)
    ->Args({0, 0})
    ->Args({1, 0})
    ->Args({0, 256})
    ->Args({1, 256})
    ->Unit(benchmark::kMillisecond);

void BM_CreateScene(benchmark::State& state) {
  const sl::drivers::SimConfig config = benchConfig(8, true);
  for (auto _ : state) {
    auto sensor = sl::drivers::SimulatedSensor::create(config);
    benchmark::DoNotOptimize(sensor.get());
  }
}
BENCHMARK(BM_CreateScene)->Unit(benchmark::kMillisecond);

// The sphere of benchConfig as a triangle mesh: an icosahedron subdivided
// `levels` times (20 * 4^levels triangles).
sl::drivers::SimMesh icosphere(int levels, double radius, const Eigen::Vector3d& center) {
  sl::drivers::SimMesh m = sl::test::unitIcosphere(levels);
  for (auto& p : m.vertices) p *= static_cast<float>(radius);
  m.pose.translation() = center;
  m.albedo = 0.7;
  return m;
}

// Scene ray casting (with ground truth and defocus set-up) with the sphere
// as a mesh of 20 * 4^levels triangles; compare BM_CreateScene (analytic).
void BM_CreateSceneMesh(benchmark::State& state) {
  sl::drivers::SimConfig config = benchConfig(8, true);
  const sl::drivers::SimSphere sphere = config.scene.spheres.front();
  config.scene.spheres.clear();
  config.scene.meshes = {icosphere(int(state.range(0)), sphere.radius, sphere.center)};
  for (auto _ : state) {
    auto sensor = sl::drivers::SimulatedSensor::create(config);
    benchmark::DoNotOptimize(sensor.get());
  }
  state.counters["triangles"] = double(config.scene.meshes.front().triangles.size());
}
BENCHMARK(BM_CreateSceneMesh)->Arg(5)->Arg(8)->Unit(benchmark::kMillisecond);

// sl_eval wall's case: a moving sensor 450 mm from a plaster wall that fills
// the view (1 mm cells, 600 x 450 mm), every pixel ray-cast exactly (the
// relief defeats the interpolation). Arg: 0 the wall as a height field
// (exact bilinear ray casting), 1 as its samples meshed (two triangles per
// cell, 540 k triangles, through the BVH).
void BM_RenderMovingWall(benchmark::State& state) {
  sl::drivers::SimConfig config = benchConfig(8, true);
  config.scene = {};
  const sl::drivers::SimHeightField wall = sl::test::plasterWall(600, 450, 450);
  if (state.range(0) == 0)
    config.scene.height_fields = {wall};
  else
    config.scene.meshes = {sl::test::heightFieldMesh(wall)};
  config.motion.velocity_mm_s = {12.5, 0, 0};
  const auto sensor = sl::drivers::SimulatedSensor::create(config);
  renderFrames(state, *sensor);
}
BENCHMARK(BM_RenderMovingWall)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
