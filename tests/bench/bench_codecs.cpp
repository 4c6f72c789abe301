// Codec throughput on 1440 x 1080 8-bit scans of a tilted plane, in scans/s:
// decode only, decode + triangulate fused per block of rows (buffers reused),
// single-threaded and split over 2 threads (rows halves; the benchmark owns
// the thread, the stages start none), the fused band form (decode +
// triangulate, no camera-sized maps), and a baseline written the
// straightforward OpenCV way (cv::phase / cv::magnitude / matrix
// expressions, determinant-tensor triangulation as matrix expressions).
//
// Patterns: 0 = 3+3 horizontal, 1 = 3+3 both, 2 = 12-step at 4 frequencies.
// Second argument: projector distortion iterations of the triangulator.
#include <cmath>
#include <cstdint>
#include <numbers>
#include <thread>
#include <vector>

#include <Eigen/Geometry>
#include <benchmark/benchmark.h>
#include <opencv2/core.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/triangulator.h"

using namespace sl::pipeline;

namespace {

CameraProjectorCalibration rig() {
  CameraProjectorCalibration c;
  c.camera = {1440, 1080, 2400, 2395, 722.4, 537.9, {-0.1, 0.05, 1e-3, -5e-4, 0.0}};
  c.projector = {1824, 1140, 2010, 1995, 905.3, 581.7, {0.06, -0.03, -6e-4, 4e-4, 0.0}};
  const Eigen::Matrix3d to_camera =
      Eigen::AngleAxisd(12.0 * std::numbers::pi / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  c.R = to_camera.transpose();
  c.t = -c.R * Eigen::Vector3d(-175.0, 0.0, 0.0);
  return c;
}

PatternSpec patternNumber(int i) {
  PatternSpec p;
  p.name = "bench";
  if (i == 1) p.direction = Direction::kBoth;
  if (i == 2) {
    p.steps = 12;
    p.frequencies = {64, 16, 4, 1};
  }
  return p;
}

struct Scene {
  CameraProjectorCalibration calibration = rig();
  cv::Mat up, vp;  // CV_64FC1 projector coordinate per camera pixel, -1 = not lit
  Scene() {
    const PinholeModel& cam = calibration.camera;
    const Eigen::Vector3d n = Eigen::Vector3d(0.28, -0.15, 1.0).normalized();
    up.create(cam.height, cam.width, CV_64FC1);
    vp.create(cam.height, cam.width, CV_64FC1);
    for (int v = 0; v < cam.height; ++v) {
      for (int u = 0; u < cam.width; ++u) {
        const Eigen::Vector2d xn = cam.pixelToNormalized({double(u), double(v)});
        const Eigen::Vector3d r(xn.x(), xn.y(), 1.0);
        const Eigen::Vector3d x = (500.0 * n.z() / n.dot(r)) * r;
        const Eigen::Vector2d q = calibration.projector.project(calibration.R * x + calibration.t);
        const bool inside = q.x() >= 0 && q.x() < 1823 && q.y() >= 0 && q.y() < 1139;
        up.at<double>(v, u) = inside ? q.x() : -1.0;
        vp.at<double>(v, u) = inside ? q.y() : -1.0;
      }
    }
  }
  std::vector<cv::Mat> render(const PatternSpec& p) const {
    std::vector<cv::Mat> frames;
    for (int f = 0; f < p.frameCount(); ++f) {
      cv::Mat image(up.size(), CV_8UC1);
      for (int v = 0; v < up.rows; ++v) {
        for (int u = 0; u < up.cols; ++u) {
          const double pu = up.at<double>(v, u), pv = vp.at<double>(v, u);
          const double lit = pu < 0 ? 0.5 : patternIntensity(p, f, pu, pv);
          image.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(std::lround(20 + 200 * lit));
        }
      }
      frames.push_back(image);
    }
    return frames;
  }
};

const Scene& scene() {
  static const Scene s;
  return s;
}

const std::vector<cv::Mat>& frames(int pattern) {
  static std::vector<cv::Mat> cache[3];
  if (cache[pattern].empty()) cache[pattern] = scene().render(patternNumber(pattern));
  return cache[pattern];
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

// Args: pattern, threads.
void BM_Decode(benchmark::State& state) {
  const auto& f = frames(int(state.range(0)));
  const int threads = int(state.range(1));
  const auto codec = makeCodec(patternNumber(int(state.range(0))), {});
  ProjectorMaps maps;
  codec->prepare(f, 8, maps);
  const int rows = f[0].rows, half = rows / 2;
  for (auto _ : state) {
    codec->prepare(f, 8, maps);
    if (threads == 1) {
      codec->decodeRows(f, 8, 0, rows, maps);
    } else {
      std::thread helper([&] { codec->decodeRows(f, 8, half, rows, maps); });
      codec->decodeRows(f, 8, 0, half, maps);
      helper.join();
    }
    benchmark::DoNotOptimize(maps.up.data);
  }
  reportScans(state);
}

// Args: pattern, projector distortion iterations, threads. Blocks of 32 rows:
// decode, then triangulate the same rows while they are in cache.
void BM_DecodeTriangulate(benchmark::State& state) {
  const auto& f = frames(int(state.range(0)));
  const auto codec = makeCodec(patternNumber(int(state.range(0))), {});
  const Triangulator triangulator(scene().calibration, withIterations(int(state.range(1))));
  const int threads = int(state.range(2));
  ProjectorMaps maps;
  PointCloud cloud;
  codec->prepare(f, 8, maps);
  triangulator.prepare(maps, cloud);
  const int rows = f[0].rows;
  auto work = [&](int begin, int end) {
    constexpr int kBlock = 32;
    for (int y = begin; y < end; y += kBlock) {
      const int y1 = std::min(y + kBlock, end);
      codec->decodeRows(f, 8, y, y1, maps);
      triangulator.triangulateRows(maps, y, y1, cloud);
    }
  };
  for (auto _ : state) {
    codec->prepare(f, 8, maps);
    triangulator.prepare(maps, cloud);
    if (threads == 1) {
      work(0, rows);
    } else {
      std::thread helper([&] { work(rows / 2, rows); });
      work(0, rows / 2);
      helper.join();
    }
    benchmark::DoNotOptimize(cloud.points.data());
  }
  state.counters["valid_points"] = double(cloud.validCount());
  reportScans(state);
}

// Args: pattern, projector distortion iterations, threads. The fused form
// for callers that need only the cloud: each thread decodes blocks of rows
// into its own small band (Codec::decodeBand) and triangulates them
// (Triangulator::triangulateBand); no camera-sized maps.
void BM_DecodeTriangulateBand(benchmark::State& state) {
  const auto& f = frames(int(state.range(0)));
  const auto codec = makeCodec(patternNumber(int(state.range(0))), {});
  const Triangulator triangulator(scene().calibration, withIterations(int(state.range(1))));
  const int threads = int(state.range(2));
  ProjectorMaps bands[2];
  PointCloud cloud;
  const int rows = f[0].rows;
  auto work = [&](int begin, int end, ProjectorMaps& band) {
    constexpr int kBlock = 16;
    for (int y = begin; y < end; y += kBlock) {
      const int y1 = std::min(y + kBlock, end);
      codec->decodeBand(f, 8, y, y1, band);
      triangulator.triangulateBand(band, y, y1, cloud);
    }
  };
  for (auto _ : state) {
    triangulator.prepareCloud("cam", 0, cloud);
    if (threads == 1) {
      work(0, rows, bands[0]);
    } else {
      std::thread helper([&] { work(rows / 2, rows, bands[1]); });
      work(0, rows / 2, bands[0]);
      helper.join();
    }
    benchmark::DoNotOptimize(cloud.points.data());
  }
  state.counters["valid_points"] = double(cloud.validCount());
  reportScans(state);
}

// The straightforward OpenCV way, 3+3 horizontal only (as sl_sensor and
// SLStudio do it): float conversion, cv::phase / cv::magnitude on matrix
// expressions, unwrapping by expressions, then z = (c0 - up c1) / (up a - b)
// with precomputed per-pixel a, b (projector distortion ignored).
struct Baseline {
  cv::Mat a, b;  // CV_32FC1
  double c0 = 0, c1 = 0;
  explicit Baseline(const CameraProjectorCalibration& c) {
    const PinholeModel& cam = c.camera;
    Eigen::Matrix<double, 3, 4> rt;
    rt.leftCols<3>() = c.R;
    rt.col(3) = c.t;
    const Eigen::Matrix<double, 3, 4> m = c.projector.K() * rt;
    a.create(cam.height, cam.width, CV_32FC1);
    b.create(cam.height, cam.width, CV_32FC1);
    for (int v = 0; v < cam.height; ++v) {
      for (int u = 0; u < cam.width; ++u) {
        const Eigen::Vector2d xn = cam.pixelToNormalized({double(u), double(v)});
        const Eigen::Vector3d r(xn.x(), xn.y(), 1.0);
        a.at<float>(v, u) = float(m.block<1, 3>(2, 0).dot(r));
        b.at<float>(v, u) = float(m.block<1, 3>(0, 0).dot(r));
      }
    }
    c0 = m(0, 3);
    c1 = m(2, 3);
  }
  cv::Mat decode(const std::vector<cv::Mat>& frames) const {
    cv::Mat_<float> i[6];
    for (int k = 0; k < 6; ++k) frames[k].convertTo(i[k], CV_32F);
    cv::Mat phase_high, phase_low, modulation;
    cv::phase(2.0f * i[0] - i[1] - i[2], std::sqrt(3.0f) * (i[1] - i[2]), phase_high);
    cv::phase(2.0f * i[3] - i[4] - i[5], std::sqrt(3.0f) * (i[4] - i[5]), phase_low);
    cv::magnitude(2.0f * i[0] - i[1] - i[2], std::sqrt(3.0f) * (i[1] - i[2]), modulation);
    cv::Mat k = (16.0f * phase_low - phase_high) / (2.0 * CV_PI);
    cv::Mat k_int;
    k.convertTo(k_int, CV_32S);  // rounds
    k_int.convertTo(k, CV_32F);
    cv::Mat up = (phase_high + 2.0 * CV_PI * k) * (1824.0 / (2.0 * CV_PI * 16.0));
    up.setTo(std::numeric_limits<float>::quiet_NaN(), modulation < 24.0f);
    return up;
  }
  cv::Mat triangulate(const cv::Mat& up) const {
    cv::Mat z = (c0 - c1 * up) / (up.mul(a) - b);
    return z;
  }
};

void BM_BaselineDecode(benchmark::State& state) {
  const auto& f = frames(0);
  const Baseline baseline(scene().calibration);
  for (auto _ : state) {
    cv::Mat up = baseline.decode(f);
    benchmark::DoNotOptimize(up.data);
  }
  reportScans(state);
}

void BM_BaselineDecodeTriangulate(benchmark::State& state) {
  const auto& f = frames(0);
  const Baseline baseline(scene().calibration);
  for (auto _ : state) {
    cv::Mat z = baseline.triangulate(baseline.decode(f));
    benchmark::DoNotOptimize(z.data);
  }
  reportScans(state);
}

}  // namespace

BENCHMARK(BM_BaselineDecode)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_BaselineDecodeTriangulate)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Decode)
    ->ArgsProduct({{0, 1, 2}, {1, 2}})
    ->ArgNames({"pattern", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_DecodeTriangulate)
    ->ArgsProduct({{0, 1, 2}, {0, 2}, {1, 2}})
    ->ArgNames({"pattern", "proj_iter", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK(BM_DecodeTriangulateBand)
    ->ArgsProduct({{0, 1, 2}, {0, 2}, {1, 2}})
    ->ArgNames({"pattern", "proj_iter", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
