// Codec throughput on 1440 x 1080 8-bit scans of a tilted plane, in scans/s,
// with real time and the CPU time of the whole process (all threads):
// - BM_Decode, BM_DecodeTriangulate: ScanProcessor, the code the daemon's
//   processing stage runs (blocks of rows decoded and triangulated on a
//   RowWorkers pool of 1 or 2 threads, buffers recycled between scans);
//   BM_DecodeTriangulate with maps:1 keeps the maps (a ScanOutput with maps
//   and cloud), with maps:0 the cloud only (ScanProcessor::Keep::kCloud, what
//   the daemon runs unless it publishes the projector maps);
// - BM_Baseline: the same 3+3 decode and triangulation written the
//   straightforward OpenCV way (float Mats, cv::phase / cv::magnitude, matrix
//   expressions), single-threaded (cv::setNumThreads(1)), its buffers kept
//   between scans as OpenCV's output arrays allow. Its counter agree_frac is
//   the fraction of its valid points within 0.01 mm of ours (proj_iter 0):
//   it computes the same thing, not a strawman.
//
// - BM_DecodeTriangulatePaced: BM_DecodeTriangulate's 3+3 cloud-only case
//   with 200 ms of idle before each scan (the daemon's cadence at 5 Hz); per
//   scan also the CPU time of all threads and of the caller, and how often a
//   thread was preempted.
//
// - BM_MemoryFloor: only the memory traffic of a 3+3 one-direction scan (the
//   frames read, the cloud and optionally the maps written), the floor the
//   processing cannot beat on this machine.
//
// - BM_DecodeHealthTally: the cloud-only scan without and with the decode
//   health tally the daemon gathers per scan.
//
// - BM_DecodeGammaCompensation: 3+3 horizontal decode with and without the
//   projector gamma compensation (decoder.projector_gamma 2.2), same frames.
//
// Patterns: 0 = 3+3 horizontal, 1 = 3+3 both, 2 = 12 steps at each of 4
// frequencies (64, 16, 4, 1 periods; 48 frames, hierarchical unwrapping).
// proj_iter: projector distortion iterations of the triangulator (0 = the
// baseline's model, which ignores projector distortion), in the epipolar
// form; BM_DecodeTriangulateAlongRay runs the reference form.
//
// - BM_DecodeBands: the decode half of the cloud-only case (blocks of rows
//   decoded into bands, not triangulated), to split BM_DecodeTriangulate.
#include <benchmark/benchmark.h>
#include <emmintrin.h>
#include <sys/resource.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <opencv2/core.hpp>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/decode_health.h"
#include "sl/pipeline/projector_response.h"
#include "sl/pipeline/row_workers.h"
#include "sl/pipeline/scan_processor.h"
#include "sl/pipeline/triangulator.h"
#include "support/test_rig.h"

using namespace sl::pipeline;

namespace {

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
  CameraProjectorCalibration calibration = sl::test::testRig();
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

CameraImages images(int pattern) {
  CameraImages i;
  i.camera_id = "cam";
  i.frames = frames(pattern);
  i.bit_depth = 8;
  return i;
}

const Codec& codec(int pattern) {
  static std::unique_ptr<Codec> cache[3];
  if (!cache[pattern]) cache[pattern] = makeCodec(patternNumber(pattern), {});
  return *cache[pattern];
}

using ProjectorCorrection = TriangulatorOptions::ProjectorCorrection;

const Triangulator& triangulator(int iterations,
                                 ProjectorCorrection method = ProjectorCorrection::kEpipolar) {
  static std::map<std::pair<int, ProjectorCorrection>, Triangulator> cache;
  const auto key = std::make_pair(iterations, method);
  auto it = cache.find(key);
  if (it == cache.end()) {
    TriangulatorOptions o;
    o.projector_distortion_iterations = iterations;
    o.projector_correction = method;
    it = cache.emplace(key, Triangulator(scene().calibration, o)).first;
  }
  return it->second;
}

// Args: pattern, threads.
// 3+3 horizontal decode with the projector's response compensated (arg
// gamma 1: decoder.projector_gamma 2.2, the phase corrected through the
// response's table) or not (0), same frames: what the compensation costs.
void BM_DecodeGammaCompensation(benchmark::State& state) {
  DecoderOptions options;
  if (state.range(0) != 0) options.projector_response = gammaResponse(2.2);
  const auto compensating = makeCodec(patternNumber(0), options);
  const CameraImages in = images(0);
  ScanProcessor processor(int(state.range(1)));
  for (auto _ : state) {
    auto maps = processor.decode(*compensating, in, 0);
    benchmark::DoNotOptimize(maps->up.data);
  }
  reportScans(state);
}

void BM_Decode(benchmark::State& state) {
  const int pattern = int(state.range(0));
  const CameraImages in = images(pattern);
  ScanProcessor processor(int(state.range(1)));
  for (auto _ : state) {
    auto maps = processor.decode(codec(pattern), in, 0);
    benchmark::DoNotOptimize(maps->up.data);
  }
  reportScans(state);
}

// The decode half of BM_DecodeTriangulate's cloud-only case: the same
// blocks of rows decoded into per-thread bands (Codec::decodeBand()), not
// triangulated. Args: pattern, threads.
void BM_DecodeBands(benchmark::State& state) {
  const int pattern = int(state.range(0));
  const CameraImages in = images(pattern);
  RowWorkers workers(int(state.range(1)));
  std::vector<ProjectorMaps> bands(workers.threads());
  for (auto _ : state) {
    workers.run(in.frames.front().rows, ScanProcessor::kBlockRows,
                [&](int begin, int end, int thread) {
                  codec(pattern).decodeBand(in.frames, in.bit_depth, begin, end, bands[thread]);
                  benchmark::DoNotOptimize(bands[thread].up.data);
                });
  }
  reportScans(state);
}

// Args: pattern, projector distortion iterations, threads, maps kept (1) or
// cloud only (0).
void BM_DecodeTriangulate(benchmark::State& state) {
  const int pattern = int(state.range(0));
  const CameraImages in = images(pattern);
  const Triangulator& t = triangulator(int(state.range(1)));
  ScanProcessor processor(int(state.range(2)));
  const auto keep =
      state.range(3) != 0 ? ScanProcessor::Keep::kMapsAndCloud : ScanProcessor::Keep::kCloud;
  std::size_t valid = 0;
  for (auto _ : state) {
    const ScanOutput out = processor.process(codec(pattern), t, in, 0, "cam", keep);
    benchmark::DoNotOptimize(out.cloud->points.data());
    if (valid == 0) valid = out.cloud->validCount();
  }
  state.counters["valid_points"] = double(valid);
  reportScans(state);
}

// BM_DecodeTriangulate's cloud-only case with the projector correction of
// the reference form (ProjectorCorrection::kAlongRay, the one shipped
// before the epipolar form): the same frames and iterations, for a
// before / after comparison in one run. Args: proj_iter, threads.
void BM_DecodeTriangulateAlongRay(benchmark::State& state) {
  const CameraImages in = images(0);
  const Triangulator& t = triangulator(int(state.range(0)), ProjectorCorrection::kAlongRay);
  ScanProcessor processor(int(state.range(1)));
  for (auto _ : state) {
    const ScanOutput out =
        processor.process(codec(0), t, in, 0, "cam", ScanProcessor::Keep::kCloud);
    benchmark::DoNotOptimize(out.cloud->points.data());
  }
  reportScans(state);
}

// The memory traffic of a 3+3 scan alone, as a floor for BM_DecodeTriangulate
// on this machine: reads the 6 frames and writes the cloud (16 bytes per
// pixel, non-temporal stores as the triangulator does) and, with maps:1, the
// maps (13 bytes per pixel), on a RowWorkers pool in the same 16-row blocks.
// Args: threads, maps.
void BM_MemoryFloor(benchmark::State& state) {
  const std::vector<cv::Mat>& in = frames(0);
  const int rows = in.front().rows, cols = in.front().cols;
  const bool maps = state.range(1) != 0;
  RowWorkers workers(int(state.range(0)));
  std::vector<PointXYZI> cloud(std::size_t(rows) * cols);
  cv::Mat up(rows, cols, CV_32FC1), modulation(rows, cols, CV_32FC1), offset(rows, cols, CV_32FC1),
      status(rows, cols, CV_8UC1);
  std::vector<std::uint32_t> sums(workers.threads());
  for (auto _ : state) {
    workers.run(rows, ScanProcessor::kBlockRows, [&](int begin, int end, int thread) {
      std::uint32_t sum = 0;
      for (const cv::Mat& f : in) {
        const auto* p = reinterpret_cast<const std::uint32_t*>(f.ptr(begin));
        for (std::size_t i = 0; i < std::size_t(end - begin) * cols / 4; ++i) sum += p[i];
      }
      sums[thread] += sum;
      float* out = &cloud[std::size_t(begin) * cols].x;
      const __m128 v = _mm_set1_ps(float(sum & 1));
      for (std::size_t i = 0; i < std::size_t(end - begin) * cols * 4; i += 4)
        _mm_stream_ps(out + i, v);
      _mm_sfence();
      if (maps) {
        for (int r = begin; r < end; ++r) {
          std::fill_n(up.ptr<float>(r), cols, 1.0f);
          std::fill_n(modulation.ptr<float>(r), cols, 2.0f);
          std::fill_n(offset.ptr<float>(r), cols, 3.0f);
          std::fill_n(status.ptr<std::uint8_t>(r), cols, std::uint8_t(0));
        }
      }
    });
    benchmark::DoNotOptimize(sums.data());
    benchmark::DoNotOptimize(cloud.data());
  }
  reportScans(state);
}

// The straightforward OpenCV way, 3+3 horizontal (as sl_sensor and SLStudio
// do it): float conversion, cv::phase / cv::magnitude on matrix expressions,
// unwrapping by expressions, then the determinant-tensor depth
// z = (c0 - up c1) / (up a - b) with per-pixel a, b precomputed once, x = z rx,
// y = z ry, and the cloud merged as x, y, z, intensity (CV_32FC4).
class Baseline {
 public:
  explicit Baseline(const CameraProjectorCalibration& c) {
    const PinholeModel& cam = c.camera;
    Eigen::Matrix<double, 3, 4> rt;
    rt.leftCols<3>() = c.R;
    rt.col(3) = c.t;
    const Eigen::Matrix<double, 3, 4> m = c.projector.K() * rt;
    a_.create(cam.height, cam.width);
    b_.create(cam.height, cam.width);
    rx_.create(cam.height, cam.width);
    ry_.create(cam.height, cam.width);
    for (int v = 0; v < cam.height; ++v) {
      for (int u = 0; u < cam.width; ++u) {
        const Eigen::Vector2d xn = cam.pixelToNormalized({double(u), double(v)});
        const Eigen::Vector3d r(xn.x(), xn.y(), 1.0);
        a_(v, u) = float(m.block<1, 3>(2, 0).dot(r));
        b_(v, u) = float(m.block<1, 3>(0, 0).dot(r));
        rx_(v, u) = float(xn.x());
        ry_(v, u) = float(xn.y());
      }
    }
    c0_ = float(m(0, 3));
    c1_ = float(m(2, 3));
  }

  // Projector column (px), NaN where B < 8 DN; offset_ = A.
  const cv::Mat& decode(const std::vector<cv::Mat>& frames) {
    for (int k = 0; k < 6; ++k) frames[k].convertTo(i_[k], CV_32F);
    const float kTwoPi = float(2.0 * CV_PI);
    // Frames 0-2: 16 periods, 3-5: 1 period; I_n = A + B cos(phi - 2 pi n / 3).
    cos_ = 2.0f * i_[0] - i_[1] - i_[2];
    sin_ = std::sqrt(3.0f) * (i_[1] - i_[2]);
    cv::phase(cos_, sin_, phase_high_);
    cv::magnitude(cos_, sin_, modulation_);  // 3 B
    cos_ = 2.0f * i_[3] - i_[4] - i_[5];
    sin_ = std::sqrt(3.0f) * (i_[4] - i_[5]);
    cv::phase(cos_, sin_, phase_low_);
    offset_ = (i_[0] + i_[1] + i_[2]) * (1.0f / 3.0f);
    // Fringe order k = round((16 phi_low - phi_high) / 2 pi).
    order_ = (16.0f * phase_low_ - phase_high_) * (1.0f / kTwoPi);
    order_.convertTo(order_int_, CV_32S);  // rounds to nearest
    order_int_.convertTo(order_, CV_32F);
    up_ = (phase_high_ + kTwoPi * order_) * float(1824.0 / (2.0 * CV_PI * 16.0));
    up_.setTo(std::numeric_limits<float>::quiet_NaN(), modulation_ < 3.0f * 8.0f);
    return up_;
  }

  // Organized cloud (CV_32FC4: x, y, z mm, intensity), NaN outside
  // [100, 3000] mm or where up is NaN.
  const cv::Mat& triangulate(const cv::Mat& up) {
    z_ = (c0_ - c1_ * up) / (up.mul(a_) - b_);
    z_.setTo(std::numeric_limits<float>::quiet_NaN(), (z_ < 100.0f) | (z_ > 3000.0f));
    x_ = z_.mul(rx_);
    y_ = z_.mul(ry_);
    const cv::Mat channels[4] = {x_, y_, z_, offset_};
    cv::merge(channels, 4, cloud_);
    return cloud_;
  }

 private:
  cv::Mat_<float> a_, b_, rx_, ry_;
  float c0_ = 0, c1_ = 0;
  cv::Mat i_[6], cos_, sin_, phase_high_, phase_low_, modulation_, offset_, order_, order_int_,
      up_, z_, x_, y_, cloud_;
};

Baseline& baseline() {
  static Baseline b(scene().calibration);
  return b;
}

// Fraction of the baseline's valid points whose z is within 0.01 mm of ours.
double baselineAgreement(const cv::Mat& cloud) {
  ScanProcessor processor(1);
  const ScanOutput ours = processor.process(codec(0), triangulator(0), images(0), 0, "cam");
  int valid = 0, agree = 0;
  for (int v = 0; v < cloud.rows; ++v) {
    for (int u = 0; u < cloud.cols; ++u) {
      const float z = cloud.at<cv::Vec4f>(v, u)[2];
      if (!std::isfinite(z)) continue;
      ++valid;
      agree += std::abs(ours.cloud->points[std::size_t(v) * cloud.cols + u].z - z) < 0.01f;
    }
  }
  return valid > 0 ? double(agree) / valid : 0.0;
}

// Arg: 0 = decode only, 1 = decode + triangulate.
void BM_Baseline(benchmark::State& state) {
  const auto& f = frames(0);
  Baseline& b = baseline();
  const bool triangulate = state.range(0) != 0;
  for (auto _ : state) {
    const cv::Mat& up = b.decode(f);
    benchmark::DoNotOptimize(up.data);
    if (triangulate) benchmark::DoNotOptimize(b.triangulate(up).data);
  }
  if (triangulate) state.counters["agree_frac"] = baselineAgreement(b.triangulate(b.decode(f)));
  reportScans(state);
}

}  // namespace

BENCHMARK(BM_Baseline)
    ->ArgName("triangulate")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();
BENCHMARK(BM_MemoryFloor)
    ->ArgsProduct({{1, 2}, {1, 0}})
    ->ArgNames({"threads", "maps"})
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();
BENCHMARK(BM_Decode)
    ->ArgsProduct({{0, 1, 2}, {1, 2}})
    ->ArgNames({"pattern", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();
BENCHMARK(BM_DecodeBands)
    ->ArgsProduct({{0, 1}, {1, 2}})
    ->ArgNames({"pattern", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();
BENCHMARK(BM_DecodeGammaCompensation)
    ->ArgsProduct({{0, 1}, {1, 2}})
    ->ArgNames({"gamma", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();
BENCHMARK(BM_DecodeTriangulate)
    ->ArgsProduct({{0, 1, 2}, {0, 2}, {1, 2}, {1, 0}})
    ->ArgNames({"pattern", "proj_iter", "threads", "maps"})
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();
BENCHMARK(BM_DecodeTriangulateAlongRay)
    ->ArgsProduct({{2}, {1, 2}})
    ->ArgNames({"proj_iter", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

// BM_DecodeTriangulate (3+3 horizontal, cloud only) at the sensor's
// cadence: the threads idle for 200 ms between scans (not timed), as the
// daemon's processing stage is at 5 Hz, so each scan starts on idle cores.
// Against BM_DecodeTriangulate's back-to-back loop it shows what idling
// costs on this machine (README, "Measured: delivery").
void BM_DecodeTriangulatePaced(benchmark::State& state) {
  const int pattern = int(state.range(0));
  const CameraImages in = images(pattern);
  const Triangulator& t = triangulator(int(state.range(1)));
  ScanProcessor processor(int(state.range(2)));
  // Per scan: CPU time of all threads and of the caller, and the times a
  // thread was preempted (two threads taking turns on one CPU show here).
  auto cpuMs = [](const rusage& r) {
    return (r.ru_utime.tv_sec + r.ru_stime.tv_sec) * 1e3 +
           (r.ru_utime.tv_usec + r.ru_stime.tv_usec) * 1e-3;
  };
  double all_ms = 0, caller_ms = 0, preempted = 0;
  for (auto _ : state) {
    state.PauseTiming();
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    rusage all0, caller0, all1, caller1;
    getrusage(RUSAGE_SELF, &all0);
    getrusage(RUSAGE_THREAD, &caller0);
    state.ResumeTiming();
    const ScanOutput out = processor.process(codec(pattern), t, in, 0, "cam", ScanProcessor::Keep::kCloud);
    benchmark::DoNotOptimize(out.cloud->points.data());
    state.PauseTiming();
    getrusage(RUSAGE_SELF, &all1);
    getrusage(RUSAGE_THREAD, &caller1);
    all_ms += cpuMs(all1) - cpuMs(all0);
    caller_ms += cpuMs(caller1) - cpuMs(caller0);
    preempted += double(all1.ru_nivcsw - all0.ru_nivcsw);
    state.ResumeTiming();
  }
  state.counters["cpu_ms"] = benchmark::Counter(all_ms, benchmark::Counter::kAvgIterations);
  state.counters["caller_cpu_ms"] = benchmark::Counter(caller_ms, benchmark::Counter::kAvgIterations);
  state.counters["preempted"] = benchmark::Counter(preempted, benchmark::Counter::kAvgIterations);
  reportScans(state);
}

BENCHMARK(BM_DecodeTriangulatePaced)
    ->ArgsProduct({{0}, {2}, {1, 2}})
    ->ArgNames({"pattern", "proj_iter", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(40)
    ->UseRealTime();

// The daemon's per-scan decode health (docs/decode-health.md): the cloud-only
// scan of BM_DecodeTriangulate without (tally:0) and with (tally:1) the
// tally of status and residual that ScanProcessor gathers block by block,
// plus judgeDecodeTally(); the difference is what decode health costs the
// daemon.
void BM_DecodeHealthTally(benchmark::State& state) {
  const bool with_tally = state.range(0) != 0;
  const int pattern = int(state.range(1));
  const CameraImages in = images(pattern);
  const Triangulator& t = triangulator(2);
  ScanProcessor processor(int(state.range(2)));
  DecodeTally tally;
  for (auto _ : state) {
    const ScanOutput out = processor.process(codec(pattern), t, in, 0, "cam", ScanProcessor::Keep::kCloud,
                                             with_tally ? &tally : nullptr);
    benchmark::DoNotOptimize(out.cloud->points.data());
    if (with_tally) {
      const DecodeHealth h = judgeDecodeTally(codec(pattern).spec(), codec(pattern).options(), tally);
      benchmark::DoNotOptimize(h.residual_median);
    }
  }
  reportScans(state);
}

// The tally alone over a decoded scan's maps (all rows at once, one thread):
// Arg 0 = status counts only (a code without consistency test), 1 = with
// the residual grid.
void BM_DecodeTallyOnly(benchmark::State& state) {
  const int pattern = 0;
  const ProjectorMaps maps = codec(pattern).decode(frames(pattern), 8);
  const bool with_residual = state.range(0) != 0;
  for (auto _ : state) {
    DecodeTally tally;
    tally.addRows(maps, 0, maps.status.rows, with_residual, 0);
    benchmark::DoNotOptimize(tally.status.data());
  }
  reportScans(state);
}

BENCHMARK(BM_DecodeTallyOnly)->ArgName("residual")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

BENCHMARK(BM_DecodeHealthTally)
    ->ArgsProduct({{0, 1}, {0, 1}, {1, 2}})
    ->ArgNames({"tally", "pattern", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->MinWarmUpTime(0.3)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

int main(int argc, char** argv) {
  // The baseline runs single-threaded and repeatably; our code does not use
  // OpenCV's threads either way.
  cv::setNumThreads(1);
  benchmark::AddCustomContext("opencv_threads", std::to_string(cv::getNumThreads()));
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
