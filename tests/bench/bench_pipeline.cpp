// Throughput of the per-scan stages on one 1440x1080 horizontal 3+3 scan
// (8-bit frames of a tilted plane rendered through a distorted camera and
// projector), single-threaded. Reported as scans/s.
#include <cmath>
#include <cstdint>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <benchmark/benchmark.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sl/pipeline/decoder.h"
#include "sl/pipeline/motion_compensation.h"
#include "sl/pipeline/row_workers.h"
#include "sl/pipeline/triangulator.h"
#include "support/test_rig.h"

using namespace sl::pipeline;

namespace {

struct Scan {
  CameraProjectorCalibration calibration = sl::test::testRig();
  PhaseShift33Pattern pattern;
  std::vector<cv::Mat> frames;  // CV_8UC1
  ProjectorMaps maps;           // decoded from frames

  Scan() {
    pattern.direction = Direction::kHorizontal;
    pattern.fringes = 16;
    const PinholeModel& cam = calibration.camera;
    // Projector column seen by each camera pixel on a tilted plane at 500 mm;
    // -1 where the projector does not reach (rendered dark).
    const Eigen::Vector3d n = Eigen::Vector3d(0.28, -0.15, 1.0).normalized();
    cv::Mat up(cam.height, cam.width, CV_64FC1);
    for (int v = 0; v < cam.height; ++v) {
      for (int u = 0; u < cam.width; ++u) {
        const Eigen::Vector2d xn = cam.pixelToNormalized({double(u), double(v)});
        const Eigen::Vector3d r(xn.x(), xn.y(), 1.0);
        const Eigen::Vector3d x = (500.0 * n.z() / n.dot(r)) * r;
        const Eigen::Vector2d q = calibration.projector.project(calibration.R * x + calibration.t);
        const bool inside = q.x() >= 0 && q.x() < 1823 && q.y() >= 0 && q.y() < 1139;
        up.at<double>(v, u) = inside ? q.x() : -1.0;
      }
    }
    for (int f = 0; f < pattern.frameCount(); ++f) {
      cv::Mat image(cam.height, cam.width, CV_8UC1);
      for (int v = 0; v < cam.height; ++v) {
        for (int u = 0; u < cam.width; ++u) {
          const double p = up.at<double>(v, u);
          const double lit = p < 0 ? 0.5 : patternIntensity(pattern, f, p, 0);
          image.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(std::lround(20 + 200 * lit));
        }
      }
      frames.push_back(image);
    }
    maps = PhaseShift33Decoder(pattern, {}).decode(frames, 8);
  }
};

const Scan& scan() {
  static const Scan s;
  return s;
}

void reportScans(benchmark::State& state) {
  state.counters["scans/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

TriangulatorOptions withIterations(int iterations) {
  TriangulatorOptions o;
  o.projector_distortion_iterations = iterations;
  return o;
}

void BM_Decode(benchmark::State& state) {
  const Scan& s = scan();
  const PhaseShift33Decoder decoder(s.pattern, {});
  for (auto _ : state) {
    ProjectorMaps maps = decoder.decode(s.frames, 8);
    benchmark::DoNotOptimize(maps.up.data);
  }
  reportScans(state);
}

// Argument: projector distortion iterations.
void BM_Triangulate(benchmark::State& state) {
  const Scan& s = scan();
  const Triangulator triangulator(s.calibration, withIterations(int(state.range(0))));
  for (auto _ : state) {
    PointCloud cloud = triangulator.triangulate(s.maps);
    benchmark::DoNotOptimize(cloud.points.data());
  }
  state.counters["valid_points"] = double(triangulator.triangulate(s.maps).validCount());
  reportScans(state);
}

void BM_DecodeAndTriangulate(benchmark::State& state) {
  const Scan& s = scan();
  const PhaseShift33Decoder decoder(s.pattern, {});
  const Triangulator triangulator(s.calibration, withIterations(int(state.range(0))));
  for (auto _ : state) {
    PointCloud cloud = triangulator.triangulate(decoder.decode(s.frames, 8));
    benchmark::DoNotOptimize(cloud.points.data());
  }
  reportScans(state);
}

void BM_TriangulatorConstruction(benchmark::State& state) {
  const Scan& s = scan();
  for (auto _ : state) {
    Triangulator triangulator(s.calibration, {});
    benchmark::DoNotOptimize(&triangulator);
  }
}

// The scan's frames times a texture moving 2 px per frame along y (the
// fringes' direction), as one camera's set for motion compensation.
ImageSet movingSet() {
  const Scan& s = scan();
  const PinholeModel& cam = s.calibration.camera;
  cv::Mat noise(cam.height + 40, cam.width, CV_32FC1), texture;
  cv::RNG(3).fill(noise, cv::RNG::NORMAL, 0, 1);
  cv::GaussianBlur(noise, texture, cv::Size(0, 0), 4);
  cv::normalize(texture, texture, 0.6, 1.0, cv::NORM_MINMAX);
  ImageSet set;
  set.cameras.resize(1);
  set.cameras[0].camera_id = "camera";
  for (std::size_t f = 0; f < s.frames.size(); ++f) {
    cv::Mat lit;
    s.frames[f].convertTo(lit, CV_32F);
    const cv::Mat moved = texture.rowRange(int(2 * f), int(2 * f) + cam.height);
    cv::Mat frame;
    cv::Mat(lit.mul(moved)).convertTo(frame, CV_8U);
    set.cameras[0].frames.push_back(frame);
    set.cameras[0].stamps_ns.push_back(std::int64_t(f) * 33'333'333);
  }
  return set;
}

// Motion compensation of that set along y, single-threaded. Argument 0: the
// whole frame shifted (no camera model), 1: through the camera's distortion
// model (MotionCompensator given the model, as the daemon does).
void BM_MotionCompensation(benchmark::State& state) {
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  const ImageSet set = movingSet();
  MotionCompensationOptions options;
  options.axis = MotionCompensationOptions::Axis::kY;
  std::map<std::string, PinholeModel> cameras;
  if (state.range(0) == 1) cameras.emplace("camera", scan().calibration.camera);
  const MotionCompensator compensator(options, cameras);
  MotionEstimate estimate;
  for (auto _ : state) {
    auto aligned = compensator.compensate(set, &estimate);
    benchmark::DoNotOptimize(aligned.get());
  }
  state.counters["shift_0_px"] = estimate.shifts_px[0][0];
  reportScans(state);
  cv::setNumThreads(threads);
}

// The same through the lens model on a RowWorkers pool of `threads` (the
// caller included), as the daemon's processing thread runs it: frames
// registered one per thread, rows resampled in blocks. OpenCV's own threads
// off. Reports the caller's CPU time (the workers' is not counted): compare
// the real time.
void BM_MotionCompensationOnWorkers(benchmark::State& state) {
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  const ImageSet set = movingSet();
  MotionCompensationOptions options;
  options.axis = MotionCompensationOptions::Axis::kY;
  const MotionCompensator compensator(options, {{"camera", scan().calibration.camera}});
  RowWorkers workers(int(state.range(0)));
  for (auto _ : state) {
    auto aligned = compensator.compensate(set, nullptr, &workers);
    benchmark::DoNotOptimize(aligned.get());
  }
  reportScans(state);
  cv::setNumThreads(threads);
}

}  // namespace

BENCHMARK(BM_MotionCompensation)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MotionCompensationOnWorkers)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Decode)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Triangulate)->Arg(0)->Arg(2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DecodeAndTriangulate)->Arg(0)->Arg(2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TriangulatorConstruction)->Unit(benchmark::kMillisecond)->Iterations(3);

BENCHMARK_MAIN();
