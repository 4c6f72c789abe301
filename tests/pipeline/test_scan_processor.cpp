// RowWorkers (every block once, exceptions, workers off the caller's CPU)
// and ScanProcessor (same maps and cloud as the single-threaded stages;
// recycled buffers never overwrite a result still held).
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <opencv2/core.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/row_workers.h"
#include "sl/pipeline/scan_processor.h"
#include "sl/pipeline/triangulator.h"
#include "support/test_rig.h"

using namespace sl::pipeline;

namespace {

// A 360 x 270 camera (a quarter of the real one) in the shared test rig.
CameraProjectorCalibration smallRig() {
  return sl::test::testRig({360, 270, 600, 599, 180.6, 134.5, {-0.1, 0.05, 1e-3, -5e-4, 0.0}});
}

// 8-bit frames of `spec` on a tilted plane around 500 mm.
CameraImages render(const CameraProjectorCalibration& c, const PatternSpec& spec) {
  const PinholeModel& cam = c.camera;
  const Eigen::Vector3d n = Eigen::Vector3d(0.28, -0.15, 1.0).normalized();
  cv::Mat up(cam.height, cam.width, CV_64FC1), vp(cam.height, cam.width, CV_64FC1);
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector2d xn = cam.pixelToNormalized({double(u), double(v)});
      const Eigen::Vector3d r(xn.x(), xn.y(), 1.0);
      const Eigen::Vector2d q = c.projector.project(c.R * ((500.0 * n.z() / n.dot(r)) * r) + c.t);
      const bool inside = q.x() >= 0 && q.x() < 1823 && q.y() >= 0 && q.y() < 1139;
      up.at<double>(v, u) = inside ? q.x() : -1.0;
      vp.at<double>(v, u) = inside ? q.y() : -1.0;
    }
  }
  CameraImages images;
  images.camera_id = "cam0";
  images.bit_depth = 8;
  for (int f = 0; f < spec.frameCount(); ++f) {
    cv::Mat image(cam.height, cam.width, CV_8UC1);
    for (int v = 0; v < cam.height; ++v) {
      for (int u = 0; u < cam.width; ++u) {
        const double pu = up.at<double>(v, u), pv = vp.at<double>(v, u);
        const double lit = pu < 0 ? 0.5 : patternIntensity(spec, f, pu, pv);
        image.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(std::lround(20 + 200 * lit));
      }
    }
    images.frames.push_back(image);
  }
  return images;
}

// Bit-for-bit equality, NaN equal to NaN.
bool sameMat(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int r = 0; r < a.rows; ++r) {
    if (std::memcmp(a.ptr(r), b.ptr(r), a.cols * a.elemSize()) != 0) return false;
  }
  return true;
}

bool sameMaps(const ProjectorMaps& a, const ProjectorMaps& b) {
  return sameMat(a.up, b.up) && sameMat(a.vp, b.vp) && sameMat(a.modulation, b.modulation) &&
         sameMat(a.offset, b.offset) && sameMat(a.status, b.status);
}

bool sameCloud(const PointCloud& a, const PointCloud& b) {
  return a.width == b.width && a.height == b.height && a.points.size() == b.points.size() &&
         std::memcmp(a.points.data(), b.points.data(), a.points.size() * sizeof(PointXYZI)) == 0;
}

}  // namespace

TEST_CASE("RowWorkers run every block exactly once", "[row_workers]") {
  const int threads = GENERATE(1, 2, 3);
  RowWorkers workers(threads);
  CHECK(workers.threads() == threads);
  for (const int rows : {1, 15, 16, 17, 1080}) {
    for (const int block : {1, 16, 2000}) {
      std::vector<std::atomic<int>> visits(rows);
      std::atomic<int> bad_blocks{0}, bad_threads{0};
      // Calls with the same thread index must not overlap.
      std::vector<std::atomic<int>> inside(threads);
      workers.run(rows, block, [&](int begin, int end, int thread) {
        if (begin % block != 0 || end - begin > block || end > rows || begin >= end) ++bad_blocks;
        if (thread < 0 || thread >= threads || inside[thread]++ != 0) {
          ++bad_threads;
          return;
        }
        for (int r = begin; r < end; ++r) ++visits[r];
        --inside[thread];
      });
      CAPTURE(threads, rows, block);
      CHECK(bad_blocks == 0);
      CHECK(bad_threads == 0);
      CHECK(std::all_of(visits.begin(), visits.end(), [](const auto& v) { return v == 1; }));
    }
  }
  CHECK_THROWS_AS(RowWorkers(0), std::invalid_argument);
}

TEST_CASE("RowWorkers rethrow the first exception and stay usable", "[row_workers]") {
  RowWorkers workers(2);
  CHECK_THROWS_WITH(workers.run(100, 1,
                                [](int begin, int, int) {
                                  if (begin == 37) throw std::runtime_error("row 37");
                                }),
                    "row 37");
  std::atomic<int> rows{0};
  workers.run(100, 7, [&](int begin, int end, int) { rows += end - begin; });
  CHECK(rows == 100);
}

TEST_CASE("RowWorkers keep their workers off the caller's CPU", "[row_workers]") {
  cpu_set_t allowed;
  REQUIRE(sched_getaffinity(0, sizeof allowed, &allowed) == 0);
  if (CPU_COUNT(&allowed) < 2) {
    WARN("one CPU available: nothing to check");
    return;
  }
  RowWorkers workers(3);
  // Pin the caller to each allowed CPU in turn: no worker may run there
  // (nor be allowed to, which is what makes the check deterministic).
  const std::thread::id caller = std::this_thread::get_id();
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (!CPU_ISSET(cpu, &allowed)) continue;
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(cpu, &one);
    REQUIRE(sched_setaffinity(0, sizeof one, &one) == 0);
    std::atomic<int> on_caller_cpu{0}, may_use_caller_cpu{0}, worker_blocks{0};
    workers.run(400, 1, [&](int, int, int) {
      if (std::this_thread::get_id() == caller) {  // leave blocks to the workers
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        return;
      }
      ++worker_blocks;
      if (sched_getcpu() == cpu) ++on_caller_cpu;
      cpu_set_t mine;
      if (sched_getaffinity(0, sizeof mine, &mine) != 0 || CPU_ISSET(cpu, &mine))
        ++may_use_caller_cpu;
    });
    CAPTURE(cpu);
    REQUIRE(worker_blocks > 0);
    CHECK(on_caller_cpu == 0);
    CHECK(may_use_caller_cpu == 0);
  }
  REQUIRE(sched_setaffinity(0, sizeof allowed, &allowed) == 0);
}

TEST_CASE("ScanProcessor equals the single-threaded stages", "[scan_processor]") {
  const CameraProjectorCalibration rig = smallRig();
  PatternSpec spec;
  spec.name = "scan";
  spec.direction = GENERATE(Direction::kHorizontal, Direction::kBoth);
  const int iterations = GENERATE(0, 2);
  const CameraImages images = render(rig, spec);
  const auto codec = makeCodec(spec, {});
  TriangulatorOptions options;
  options.projector_distortion_iterations = iterations;
  const Triangulator triangulator(rig, options);

  ProjectorMaps maps = codec->decode(images.frames, 8);
  maps.camera_id = "cam0";
  maps.stamp_ns = 42;
  const PointCloud cloud = triangulator.triangulate(maps);
  REQUIRE(cloud.validCount() > 50000);

  ScanProcessor processor(2);
  const ScanOutput out = processor.process(*codec, triangulator, images, 42, "cam0_optical");
  CHECK(sameMaps(*out.maps, maps));
  CHECK(sameCloud(*out.cloud, cloud));
  CHECK(out.maps->camera_id == "cam0");
  CHECK(out.maps->stamp_ns == 42);
  CHECK(out.cloud->frame_id == "cam0_optical");
  CHECK(out.cloud->stamp_ns == 42);
  CHECK(sameMaps(*processor.decode(*codec, images, 42), maps));

  // Cloud only: the same cloud, no maps.
  const ScanOutput cloud_only = processor.process(*codec, triangulator, images, 42, "cam0_optical",
                                                  ScanProcessor::Keep::kCloud);
  CHECK(cloud_only.maps == nullptr);
  CHECK(sameCloud(*cloud_only.cloud, cloud));
  CHECK(cloud_only.cloud->frame_id == "cam0_optical");
  CHECK(cloud_only.cloud->stamp_ns == 42);
}

TEST_CASE("ScanProcessor rejects frames that do not fit the calibration", "[scan_processor]") {
  const CameraProjectorCalibration rig = smallRig();
  PatternSpec spec;
  spec.name = "scan";
  CameraImages images = render(rig, spec);
  for (cv::Mat& f : images.frames) f = f.rowRange(0, f.rows - 8).clone();
  const auto codec = makeCodec(spec, {});
  const Triangulator triangulator(rig, {});
  ScanProcessor processor(2);
  for (const auto keep : {ScanProcessor::Keep::kMapsAndCloud, ScanProcessor::Keep::kCloud}) {
    CHECK_THROWS_AS(processor.process(*codec, triangulator, images, 1, "f", keep),
                    std::invalid_argument);
  }
  images.frames.pop_back();
  CHECK_THROWS_WITH(
      processor.process(*codec, triangulator, images, 1, "f", ScanProcessor::Keep::kCloud),
      Catch::Contains("expected 6 frames"));
}

TEST_CASE("ScanProcessor recycles only released buffers", "[scan_processor]") {
  const CameraProjectorCalibration rig = smallRig();
  PatternSpec horizontal;
  horizontal.name = std::string("h");
  PatternSpec vertical;
  vertical.name = std::string("v");
  vertical.direction = Direction::kVertical;
  const auto codec_h = makeCodec(horizontal, {});
  const auto codec_v = makeCodec(vertical, {});
  const CameraImages images_h = render(rig, horizontal);
  const CameraImages images_v = render(rig, vertical);
  const Triangulator triangulator(rig, {});
  ScanProcessor processor(2);

  ScanOutput held = processor.process(*codec_h, triangulator, images_h, 1, "f");
  const ProjectorMaps held_copy{held.maps->camera_id, held.maps->stamp_ns,
                                held.maps->up.clone(),  held.maps->vp.clone(),
                                held.maps->modulation.clone(), held.maps->offset.clone(),
                                held.maps->status.clone()};
  const PointCloud held_cloud = *held.cloud;
  // While held, a result is not reused: the next scans get other buffers.
  const ProjectorMaps* second_maps = nullptr;
  const PointCloud* second_cloud = nullptr;
  {
    const ScanOutput other = processor.process(*codec_v, triangulator, images_v, 2, "f");
    CHECK(other.maps != held.maps);
    CHECK(other.cloud != held.cloud);
    second_maps = other.maps.get();
    second_cloud = other.cloud.get();
    // Vertical: up is NaN everywhere, vp decoded.
    CHECK(cv::countNonZero(other.maps->up == other.maps->up) == 0);
    CHECK(cv::countNonZero(other.maps->vp == other.maps->vp) > 50000);
  }
  CHECK(sameMaps(*held.maps, held_copy));
  CHECK(sameCloud(*held.cloud, held_cloud));
  // Released buffers are reused (the cloud at once; the maps for a codec of
  // the same direction).
  {
    const ScanOutput again = processor.process(*codec_v, triangulator, images_v, 3, "f");
    CHECK(again.maps.get() == second_maps);
    CHECK(again.cloud.get() == second_cloud);
  }
  // The only free maps buffer is the vertical one: a horizontal scan must not
  // inherit its decoded vp (vp NaN everywhere), and `held` stays intact.
  const ScanOutput h2 = processor.process(*codec_h, triangulator, images_h, 4, "f");
  CHECK(h2.maps != held.maps);
  CHECK(cv::countNonZero(h2.maps->vp == h2.maps->vp) == 0);
  CHECK(sameMat(h2.maps->up, held_copy.up));
  CHECK(sameMaps(*held.maps, held_copy));
}
