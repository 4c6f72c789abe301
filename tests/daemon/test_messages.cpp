// The DDS edge without DDS: the samples built from pipeline and engine values
// (daemon/src/ros_messages.h), request dispatch against a fake sensor
// (daemon/src/request_dispatch.h) and the frame-id decisions (FrameIds).
#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <type_traits>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/set_processor.h"
#include "request_dispatch.h"
#include "ros_messages.h"
#include "velocity_input.h"
#include "sl/daemon/config.h"
#include "sl/daemon/dds_bridge.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/point_quality.h"
#include "sl_msgs/ros2_definitions.h"

using namespace sl::daemon;
using ::sl::dds::CloudLayout;
using ::sl::client::CommandResult;
using ::sl::dds::PackedCloud;
using ::sl::dds::PointQuality;
using ::sl::client::ScanState;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;
using ::sl::dds::floatsPerPoint;
using ::sl::dds::maxPackedBytes;
using ::sl::dds::packCloud;
using ::sl::dds::packsInPlace;
using Code = CommandResult::Code;

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr sl::pipeline::TimestampNs kStamp = 1'700'000'001'250'000'000;

std::string str(const char* s) { return s ? s : "<null>"; }

template <typename Seq>
std::vector<std::string> strings(const Seq& seq) {
  std::vector<std::string> out;
  for (std::uint32_t i = 0; i < seq._length; ++i) out.push_back(seq._buffer[i]);
  return out;
}

// A 3 x 2 cloud in mm; pixel (1, 0) invalid.
sl::pipeline::PointCloud smallCloud() {
  sl::pipeline::PointCloud c;
  c.width = 3;
  c.height = 2;
  c.stamp_ns = kStamp;
  for (int i = 0; i < 6; ++i) c.points.push_back({10.f * i, -5.f * i, 500.f + i, 100.f * i});
  c.points[1] = {kNaN, kNaN, kNaN, kNaN};
  return c;
}

}  // namespace

TEST_CASE("cloud message: x, y, z, intensity float32, 16 bytes a point, metres, the given frame") {
  const sl::pipeline::PointCloud cloud = smallCloud();
  std::vector<float> buffer;
  const PackedCloud packed = packCloud(cloud, 1e-3, CloudLayout{}, buffer);
  const msg::CloudMessage message(packed, cloud.stamp_ns, "cam_optical");
  const msg::PointCloud2& m = message.sample();
  CHECK(str(m.header.frame_id) == "cam_optical");
  CHECK(m.header.stamp.sec == 1'700'000'001);
  CHECK(m.header.stamp.nanosec == 250'000'000u);
  CHECK(m.width == 3);
  CHECK(m.height == 2);
  REQUIRE(m.fields._length == 4);
  const char* names[4] = {"x", "y", "z", "intensity"};
  for (std::uint32_t i = 0; i < 4; ++i) {
    CHECK(str(m.fields._buffer[i].name) == names[i]);
    CHECK(m.fields._buffer[i].offset == 4 * i);
    CHECK(m.fields._buffer[i].datatype == msg::kFloat32);
    CHECK(m.fields._buffer[i].count == 1);
  }
  CHECK(m.point_step == 16);
  CHECK(m.row_step == 48);
  CHECK_FALSE(m.is_bigendian);
  CHECK_FALSE(m.is_dense);  // organized, may hold NaN points
  REQUIRE(m.data._length == 6 * 16);
  CHECK_FALSE(m.data._release);  // borrowed: the writer must not free it
  float p[4];
  std::memcpy(p, m.data._buffer + 5 * 16, sizeof p);
  CHECK(p[0] == Approx(0.050f));
  CHECK(p[1] == Approx(-0.025f));
  CHECK(p[2] == Approx(0.505f));
  CHECK(p[3] == 500.f);  // intensity in camera DN, not scaled
  std::memcpy(p, m.data._buffer + 1 * 16, sizeof p);
  CHECK(std::isnan(p[2]));
}

TEST_CASE("cloud message with normals and confidence: PCL's field names, 32 bytes a point",
          "[quality]") {
  const sl::pipeline::PointCloud cloud = smallCloud();
  PointQuality quality;
  quality.normals = cv::Mat(2, 3, CV_32FC3);
  quality.depth_sigma = cv::Mat(2, 3, CV_32FC1);
  for (int v = 0; v < 2; ++v)
    for (int u = 0; u < 3; ++u) {
      const float k = static_cast<float>(3 * v + u);
      quality.normals.at<cv::Vec3f>(v, u) = {0.1f * k, -0.2f * k, -1.0f - k};
      quality.depth_sigma.at<float>(v, u) = 0.05f + 0.01f * k;  // mm, as the cloud
    }
  quality.depth_sigma.at<float>(0, 1) = kNaN;
  std::vector<float> buffer;
  struct Case {
    bool normals, confidence;
    std::vector<std::string> names;
  };
  const Case cases[] = {
      {true, true, {"x", "y", "z", "intensity", "normal_x", "normal_y", "normal_z", "confidence"}},
      {true, false, {"x", "y", "z", "intensity", "normal_x", "normal_y", "normal_z"}},
      {false, true, {"x", "y", "z", "intensity", "confidence"}},
  };
  for (const Case& c : cases) {
    CloudLayout layout;
    layout.normals = c.normals;
    layout.confidence = c.confidence;
    INFO("normals " << c.normals << ", confidence " << c.confidence);
    CHECK_FALSE(packsInPlace(layout, 1.0));  // the optional fields never go in place
    const std::uint32_t step = 4 * static_cast<std::uint32_t>(c.names.size());
    CHECK(floatsPerPoint(layout) * 4 == static_cast<int>(step));
    CHECK(maxPackedBytes(3, 2, layout) == 6 * step);
    const PackedCloud packed = packCloud(cloud, 1e-3, layout, buffer, &quality);
    const msg::CloudMessage message(packed, cloud.stamp_ns, "cam_optical");
    const msg::PointCloud2& m = message.sample();
    REQUIRE(m.fields._length == c.names.size());
    for (std::uint32_t i = 0; i < m.fields._length; ++i) {
      CHECK(str(m.fields._buffer[i].name) == c.names[i]);
      CHECK(m.fields._buffer[i].offset == 4 * i);
      CHECK(m.fields._buffer[i].datatype == msg::kFloat32);
      CHECK(m.fields._buffer[i].count == 1);
    }
    CHECK(m.point_step == step);
    CHECK(m.row_step == 3 * step);
    REQUIRE(m.data._length == 6 * step);
    std::vector<float> p(c.names.size());
    std::memcpy(p.data(), m.data._buffer + 5 * step, step);  // pixel (2, 1)
    CHECK(p[2] == Approx(0.505f));
    CHECK(p[3] == 500.f);
    std::size_t next = 4;
    if (c.normals) {
      CHECK(p[4] == Approx(0.5f));  // unit vectors: not scaled
      CHECK(p[5] == Approx(-1.0f));
      CHECK(p[6] == -6.0f);
      next = 7;
    }
    if (c.confidence) {
      CHECK(p[next] == Approx(0.10e-3f));  // metres
      std::memcpy(p.data(), m.data._buffer + 1 * step, step);  // pixel (1, 0): NaN point
      CHECK(std::isnan(p[next]));
    }
  }
  SECTION("decimated and valid only keep each point's own quality") {
    CloudLayout layout{1, true, true, true};
    const PackedCloud packed = packCloud(cloud, 1e-3, layout, buffer, &quality);
    REQUIRE(packed.width == 5);  // pixel (1, 0) dropped
    REQUIRE(packed.point_step == 32);
    float p[8];
    std::memcpy(p, packed.data + 1 * 32, sizeof p);  // pixel (2, 0), k = 2
    CHECK(p[4] == Approx(0.2f));
    CHECK(p[7] == Approx(0.07e-3f));
    layout = CloudLayout{2, false, false, true};
    const PackedCloud decimated = packCloud(cloud, 1e-3, layout, buffer, &quality);
    REQUIRE((decimated.width == 2 && decimated.height == 1 && decimated.point_step == 20));
    std::memcpy(p, decimated.data + 20, 20);  // pixel (2, 0)
    CHECK(p[4] == Approx(0.07e-3f));
  }
  SECTION("a field asked for but not computed is an error naming it") {
    CloudLayout layout;
    layout.confidence = true;
    CHECK_THROWS_WITH(packCloud(cloud, 1e-3, layout, buffer, nullptr),
                      Catch::Contains("confidence"));
    PointQuality wrong;
    wrong.depth_sigma = cv::Mat(3, 3, CV_32FC1, 0.0f);
    CHECK_THROWS_WITH(packCloud(cloud, 1e-3, layout, buffer, &wrong), Catch::Contains("3 x 3"));
    layout = CloudLayout{};
    layout.normals = true;
    CHECK_THROWS_WITH(packCloud(cloud, 1e-3, layout, buffer, &wrong), Catch::Contains("normals"));
  }
}

TEST_CASE("set processing: the per-point quality is depthSigma and organizedNormals of the whole scan",
          "[quality]") {
  // The set processor computes it in blocks of rows on its workers: every
  // value must be the whole-image functions' (bit for bit, NaN included).
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(SL_SOURCE_DIR "/config/sim.yaml");
  REQUIRE(config.camera_noise);
  const std::string pattern = "3+3_horizontal", id = config.sim.camera_id;
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  sl::pipeline::ImageSet set;
  set.pattern_name = pattern;
  set.sequence_id = 1;
  set.trigger_stamp_ns = kStamp;
  sl::pipeline::CameraImages images;
  images.camera_id = id;
  images.bit_depth = 8;
  const int frames = config.findPattern(pattern)->frameCount();
  for (int i = 0; i < frames; ++i) {
    images.frames.push_back(sim->render(pattern, i, 7 + i));
    images.stamps_ns.push_back(kStamp + i);
  }
  set.cameras.push_back(images);
  for (const double unit_mm : {1.0, 1000.0}) {
    INFO("cloud unit " << unit_mm << " mm");
    sl::daemon::ProcessingConfig processing = sl::daemon::processingConfigOf(config, {id}, unit_mm, true);
    processing.depth_sigma = true;
    processing.normals = true;
    processing.normal_step = 4;
    sl::daemon::SetProcessor processor(processing);
    const sl::daemon::SetOutcome out = processor.process(set, {id}, false);
    INFO("error: " << out.error);
    REQUIRE(out.ok());
    const sl::daemon::CameraScan& scan = out.scans.at(0);
    REQUIRE(scan.quality);
    REQUIRE(scan.maps);
    sl::pipeline::CameraNoise noise = *config.camera_noise;
    noise.bit_depth = 8;
    const cv::Mat sigma = sl::pipeline::depthSigma(
        *scan.maps, *scan.cloud, sl::pipeline::inUnits(config.calibration, 1.0 / unit_mm),
        *config.findPattern(pattern), noise, config.triangulator.use);
    const cv::Mat normals =
        sl::pipeline::organizedNormals(*scan.cloud, 4, static_cast<float>(5.0 / unit_mm));
    REQUIRE(scan.quality->depth_sigma.size() == sigma.size());
    REQUIRE(scan.quality->normals.size() == normals.size());
    CHECK(sigma.total() * sizeof(float) == sigma.step[0] * sigma.rows);
    CHECK(std::memcmp(scan.quality->depth_sigma.data, sigma.data, sigma.total() * sizeof(float)) == 0);
    CHECK(std::memcmp(scan.quality->normals.data, normals.data, normals.total() * 3 * sizeof(float)) == 0);
    std::size_t finite = 0;
    for (int r = 0; r < sigma.rows; ++r)
      for (int c = 0; c < sigma.cols; ++c) finite += std::isfinite(sigma.at<float>(r, c));
    CHECK(finite > sigma.total() / 2);  // not a comparison of two NaN images
  }
}

TEST_CASE("depth and shading images: 32FC1 metres with NaN, mono8 scaled from the bit depth") {
  sl::pipeline::PointCloud cloud = smallCloud();
  cloud.points[2].intensity = 4095.f;  // the 12-bit maximum
  cloud.points[3].intensity = 5000.f;  // beyond it: clamped
  const msg::ScanImages images(cloud, 1e-3, 12, "cam_optical");
  const msg::Image& depth = images.depth();
  const msg::Image& shading = images.shading();
  CHECK(str(depth.encoding) == "32FC1");
  CHECK(str(shading.encoding) == "mono8");
  for (const msg::Image* image : {&depth, &shading}) {
    CHECK(str(image->header.frame_id) == "cam_optical");
    CHECK(image->header.stamp.sec == 1'700'000'001);
    CHECK(image->width == 3);
    CHECK(image->height == 2);
    CHECK(image->is_bigendian == 0);
  }
  CHECK(depth.step == 12);
  CHECK(shading.step == 3);
  REQUIRE(depth.data._length == 24);
  REQUIRE(shading.data._length == 6);
  std::vector<float> z(6);
  std::memcpy(z.data(), depth.data._buffer, 24);
  CHECK(z[0] == Approx(0.500f));
  CHECK(std::isnan(z[1]));
  CHECK(z[5] == Approx(0.505f));
  const std::uint8_t* a = shading.data._buffer;
  CHECK(a[0] == 0);
  CHECK(a[1] == 0);    // invalid
  CHECK(a[2] == 255);  // 4095 of 12 bits
  CHECK(a[3] == 255);  // clamped
  CHECK(a[4] == static_cast<int>(400.f * 255.f / 4095.f + 0.5f));
  // 8-bit cameras: intensities are already 8 bit.
  const msg::ScanImages eight(cloud, 1e-3, 8, "f");
  CHECK(eight.shading().data._buffer[4] == 255);  // 400 DN clamped
  CHECK(eight.shading().data._buffer[0] == 0);
}

TEST_CASE("camera_info: plumb_bob, K and P from the intrinsics, R the identity") {
  sl::pipeline::PinholeModel camera;
  camera.width = 1440;
  camera.height = 1080;
  camera.fx = 2400;
  camera.fy = 2410;
  camera.cx = 719.5;
  camera.cy = 539.5;
  camera.distortion = {-0.08, 0.12, 0.0005, -0.0003, 0};
  const msg::CameraInfoMessage message(camera, kStamp, "sl_camera_optical_frame");
  const msg::CameraInfo& m = message.sample();
  CHECK(str(m.header.frame_id) == "sl_camera_optical_frame");
  CHECK(m.header.stamp.nanosec == 250'000'000u);
  CHECK(m.width == 1440);
  CHECK(m.height == 1080);
  CHECK(str(m.distortion_model) == "plumb_bob");
  REQUIRE(m.d._length == 5);
  CHECK(m.d._buffer[0] == -0.08);
  CHECK(m.d._buffer[3] == -0.0003);
  const double k[9] = {2400, 0, 719.5, 0, 2410, 539.5, 0, 0, 1};
  const double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  const double p[12] = {2400, 0, 719.5, 0, 0, 2410, 539.5, 0, 0, 0, 1, 0};
  for (int i = 0; i < 9; ++i) CHECK(m.k[i] == k[i]);
  for (int i = 0; i < 9; ++i) CHECK(m.r[i] == r[i]);
  for (int i = 0; i < 12; ++i) CHECK(m.p[i] == p[i]);
}

TEST_CASE("camera_info of the rectified depth image: D = 0, the same K, P = [K | 0]") {
  sl::pipeline::PinholeModel camera;
  camera.width = 64;
  camera.height = 48;
  camera.fx = 80;
  camera.fy = 81;
  camera.cx = 31.5;
  camera.cy = 23.5;
  camera.distortion = {-0.08, 0.12, 0.0005, -0.0003, 0.01};
  const msg::CameraInfoMessage message(camera, kStamp, "f", true);
  const msg::CameraInfo& m = message.sample();
  CHECK(str(m.distortion_model) == "plumb_bob");
  REQUIRE(m.d._length == 5);
  for (int i = 0; i < 5; ++i) CHECK(m.d._buffer[i] == 0.0);
  const double p[12] = {80, 0, 31.5, 0, 0, 81, 23.5, 0, 0, 0, 1, 0};
  for (int i = 0; i < 12; ++i) CHECK(m.p[i] == p[i]);
  CHECK(m.k[0] == 80);
  CHECK(m.k[4] == 81);
}

TEST_CASE("depth rectification: each rectified pixel's ray meets the raw image where its depth is read") {
  sl::pipeline::PinholeModel camera;
  camera.width = 64;
  camera.height = 48;
  camera.fx = 60;
  camera.fy = 60;
  camera.cx = 31.5;
  camera.cy = 23.5;
  camera.distortion = {0.2, 0.05, 0.001, -0.001, 0};  // pincushion
  // A raw depth image that varies linearly with the raw pixel: bilinear
  // resampling reproduces it exactly where its 4 pixels are valid.
  std::vector<float> raw(64 * 48);
  for (int v = 0; v < 48; ++v)
    for (int u = 0; u < 64; ++u) raw[v * 64 + u] = 1.0f + 0.001f * u + 0.002f * v;
  raw[20 * 64 + 30] = kNaN;
  const DepthRectifier rectifier(camera);
  const msg::RectifiedDepthMessage message(raw, rectifier, kStamp, "f");
  const msg::Image& m = message.sample();
  CHECK(str(m.encoding) == "32FC1");
  CHECK(m.width == 64);
  CHECK(m.height == 48);
  CHECK(m.step == 256);
  REQUIRE(m.data._length == 64 * 48 * 4);
  std::vector<float> z(64 * 48);
  std::memcpy(z.data(), m.data._buffer, m.data._length);
  int checked = 0, invalid_near_nan = 0, outside = 0;
  for (int v = 0; v < 48; ++v)
    for (int u = 0; u < 64; ++u) {
      const Eigen::Vector2d at = camera.normalizedToPixel({(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy});
      const float got = z[v * 64 + u];
      const bool inside = at.x() >= 0 && at.y() >= 0 && at.x() <= 63 && at.y() <= 47;
      const bool near_nan = std::abs(at.x() - 30) < 1 && std::abs(at.y() - 20) < 1;
      if (!inside) {
        outside += std::isnan(got);
        CHECK(std::isnan(got));
      } else if (near_nan) {
        invalid_near_nan += std::isnan(got);
        CHECK(std::isnan(got));
      } else {
        REQUIRE(std::isfinite(got));
        CHECK(got == Approx(1.0 + 0.001 * at.x() + 0.002 * at.y()).epsilon(1e-6));
        ++checked;
      }
    }
  CHECK(checked > 64 * 48 / 2);
  CHECK(invalid_near_nan >= 1);
  CHECK(outside > 0);  // the rectified corners see past the raw image (pincushion)
  // A depth edge within one pixel is not blended into an invented surface.
  std::vector<float> edge(64 * 48, 1.0f);
  for (int v = 0; v < 48; ++v)
    for (int u = 32; u < 64; ++u) edge[v * 64 + u] = 2.0f;
  std::vector<float> out;
  rectifier.rectify(edge, out);
  for (float d : out) CHECK((std::isnan(d) || d == 1.0f || d == 2.0f));
  CHECK_THROWS_WITH(rectifier.rectify(std::vector<float>(10), out),
                    Catch::Contains("10 pixels for a 64x48 camera"));
}

TEST_CASE("compressed images: image_transport's png and compressedDepth formats") {
  sl::pipeline::PointCloud cloud = smallCloud();
  const msg::ScanImages images(cloud, 1e-3, 12, "cam_optical");
  const msg::CompressedPngMessage png(images.shading(), 1);
  CHECK(str(png.sample().format) == "mono8; png compressed ");
  CHECK(str(png.sample().header.frame_id) == "cam_optical");
  CHECK(png.sample().header.stamp.sec == 1'700'000'001);
  REQUIRE(png.sample().data._length > 8);
  CHECK(png.sample().data._buffer[1] == 'P');
  const msg::CompressedDepthMessage depth(images.depth(), 1);
  const msg::CompressedImage& d = depth.sample();
  CHECK(str(d.format) == "32FC1; compressedDepth png");
  REQUIRE(d.data._length > 12 + 8);
  std::int32_t kind = -1;
  float a = 0, b = 0;
  std::memcpy(&kind, d.data._buffer, 4);
  std::memcpy(&a, d.data._buffer + 4, 4);
  std::memcpy(&b, d.data._buffer + 8, 4);
  CHECK(kind == 0);
  CHECK(a == 10100.0f);
  CHECK(b == 1.0f - 10100.0f / 10.0f);
  CHECK(d.data._buffer[12 + 1] == 'P');
  CHECK_THROWS_WITH(msg::CompressedPngMessage(images.depth(), 1), Catch::Contains("'32FC1' is not mono8"));
  CHECK_THROWS_WITH(msg::CompressedDepthMessage(images.shading(), 1), Catch::Contains("'mono8' is not 32FC1"));
}

TEST_CASE("projector maps: missing maps are NaN, non-continuous maps are copied row by row") {
  sl::pipeline::ProjectorMaps maps;
  maps.stamp_ns = kStamp;
  cv::Mat wide(3, 5, CV_32FC1);
  for (int v = 0; v < 3; ++v)
    for (int u = 0; u < 5; ++u) wide.at<float>(v, u) = float(10 * v + u);
  maps.up = wide(cv::Rect(1, 0, 4, 3));  // not continuous
  REQUIRE_FALSE(maps.up.isContinuous());
  maps.vp = cv::Mat(3, 4, CV_32FC1, cv::Scalar(7.5f));
  maps.status = cv::Mat(3, 4, CV_8UC1, cv::Scalar(0));
  maps.status.at<std::uint8_t>(2, 3) = 4;
  const msg::MapsMessage message(maps, "3+3_horizontal", 12, "sl_camera_optical_frame");
  const msg::Maps& m = message.sample();
  CHECK(str(m.pattern) == "3+3_horizontal");
  CHECK(m.scan_index == 12);
  CHECK(str(m.header.frame_id) == "sl_camera_optical_frame");
  CHECK(m.width == 4);
  CHECK(m.height == 3);
  REQUIRE(m.up._length == 12);
  CHECK(m.up._buffer[0] == 1.f);
  CHECK(m.up._buffer[4] == 11.f);  // row 1 starts at column 1 of the wide map
  CHECK(m.up._buffer[11] == 24.f);
  CHECK(m.vp._buffer[5] == 7.5f);
  REQUIRE(m.modulation._length == 12);
  CHECK(std::isnan(m.modulation._buffer[0]));  // not computed: NaN
  CHECK(m.status._buffer[11] == 4);
}

TEST_CASE("image set: camera-major images stamped by exposure, in each camera's optical frame") {
  sl::pipeline::ImageSet set;
  set.sequence_id = 42;
  set.pattern_name = "3+3_both";
  set.trigger_stamp_ns = kStamp;
  sl::pipeline::CameraImages top{"top", {}, {}, 8}, side{"side", {}, {}, 12};
  for (int f = 0; f < 2; ++f) {
    top.frames.push_back(cv::Mat(4, 6, CV_8UC1, cv::Scalar(f + 1)));
    top.stamps_ns.push_back(kStamp + f * 1000);
  }
  const cv::Mat wide(4, 8, CV_16UC1, cv::Scalar(300));
  side.frames.push_back(wide(cv::Rect(2, 0, 6, 4)));  // not continuous: copied
  side.stamps_ns.push_back(kStamp + 5000);
  set.cameras = {top, side};
  const msg::ImageSetMessage message(set, {"sl_camera_optical_frame", "side_optical_frame"});
  const msg::ImageSetMsg& m = message.sample();
  CHECK(m.sequence_id == 42);
  CHECK(str(m.pattern) == "3+3_both");
  CHECK(m.camera_count == 2);
  CHECK(strings(m.camera_ids) == std::vector<std::string>{"top", "side"});
  REQUIRE(m.bit_depths._length == 2);
  CHECK(m.bit_depths._buffer[0] == 8);
  CHECK(m.bit_depths._buffer[1] == 12);
  REQUIRE(m.images._length == 3);
  const msg::Image& second = m.images._buffer[1];
  CHECK(str(second.header.frame_id) == "sl_camera_optical_frame");
  CHECK(second.header.stamp.nanosec == 250'001'000u);
  CHECK(str(second.encoding) == "mono8");
  CHECK(second.step == 6);
  CHECK(second.data._buffer[0] == 2);
  const msg::Image& third = m.images._buffer[2];
  CHECK(str(third.header.frame_id) == "side_optical_frame");
  CHECK(str(third.encoding) == "mono16");
  CHECK(third.step == 12);
  REQUIRE(third.data._length == 48);
  std::uint16_t last = 0;
  std::memcpy(&last, third.data._buffer + 46, 2);
  CHECK(last == 300);
  CHECK_THROWS_AS(msg::ImageSetMessage(set, {"only_one"}), std::invalid_argument);
}

TEST_CASE("status: the engine's values and the edge's counters; timed-out writes count as dropped sets") {
  EngineStatus s;
  s.state = ScanState::kDegraded;
  s.pattern = "3+3_horizontal";
  s.scans_done = 7;
  s.sets_dropped = 2;
  s.sets_overflow = 2;
  s.degraded_reason = "camera 'top': no frame for 2.4 s";
  s.trigger = TriggerMode::kSoftware;
  s.cameras = {"top", "side"};
  s.last_error_ns = kStamp;
  s.decode_modulated_fraction = 0.61;
  s.decode_consistent_fraction = 0.58;
  s.decode_residual_median = 0.25;
  s.clouds_implausible = 11;
  s.adaptive_mode = "linear_x";
  s.adaptive_reason = "linear along x at 0.0600 m/s";
  s.adaptive_switches = 12;
  msg::EdgeCounters edge;
  edge.requests.received = 9;
  edge.requests.answered = 8;
  edge.requests.rate_limited = 1;
  edge.replies_timed_out = 3;
  edge.requests_malformed = 4;
  edge.writes_timed_out = 5;
  edge.requests_rejected = 6;
  edge.clouds_lost_to_readers = 7;
  edge.images_not_compressed = 12;
  edge.points_readers = {{"1:2:3:4", true, false, 7}, {"5:6:7:8", false, true, 0}};
  const msg::StatusMessage message(s, {"a", "b", "c"}, edge, kStamp + 1);
  const msg::Status& m = message.sample();
  CHECK(m.state == sl_msgs_msg_dds__Status_Constants_STATE_DEGRADED);
  CHECK(str(m.pattern) == "3+3_horizontal");
  CHECK(m.scans_done == 7);
  CHECK(m.sets_dropped == 2 + 5);
  CHECK(m.sets_overflow == 2);
  CHECK(m.writes_timed_out == 5);
  CHECK(m.trigger == sl_msgs_msg_dds__Status_Constants_TRIGGER_SOFTWARE);
  CHECK(strings(m.cameras) == std::vector<std::string>{"top", "side"});
  CHECK(strings(m.patterns) == std::vector<std::string>{"a", "b", "c"});
  CHECK(str(m.degraded_reason) == "camera 'top': no frame for 2.4 s");
  CHECK(m.requests_received == 9);
  CHECK(m.requests_answered == 8);
  CHECK(m.requests_rate_limited == 1);
  CHECK(m.replies_timed_out == 3);
  CHECK(m.requests_malformed == 4);
  CHECK(m.requests_rejected == 6);
  CHECK(m.clouds_lost_to_readers == 7);
  CHECK(m.decode_modulated_fraction == 0.61);
  CHECK(m.decode_consistent_fraction == 0.58);
  CHECK(m.decode_residual_median == 0.25);
  CHECK(m.clouds_implausible == 11);
  CHECK(m.images_not_compressed == 12);
  CHECK(str(m.adaptive_mode) == "linear_x");
  CHECK(str(m.adaptive_reason) == "linear along x at 0.0600 m/s");
  CHECK(m.adaptive_switches == 12);
  REQUIRE(m.points_readers._length == 2);
  CHECK(str(m.points_readers._buffer[0].guid) == "1:2:3:4");
  CHECK(m.points_readers._buffer[0].reliable);
  CHECK_FALSE(m.points_readers._buffer[0].acknowledging);
  CHECK(m.points_readers._buffer[0].clouds_lost == 7);
  CHECK(str(m.points_readers._buffer[1].guid) == "5:6:7:8");
  CHECK_FALSE(m.points_readers._buffer[1].reliable);
  CHECK(m.stamp.nanosec == 250'000'001u);
  CHECK(m.last_error_stamp.sec == 1'700'000'001);
  CHECK(msg::toState(ScanState::kIdle) == sl_msgs_msg_dds__Status_Constants_STATE_IDLE);
  CHECK(msg::toState(ScanState::kWaiting) == sl_msgs_msg_dds__Status_Constants_STATE_WAITING);
}

// Status.msg's fields (not its constants): name -> type.
std::map<std::string, std::string> statusMsgFields() {
  for (const auto& d : sl_msgs_definitions::kMessages) {
    if (std::string(d.type) != "sl_msgs/Status") continue;
    std::map<std::string, std::string> fields;
    std::istringstream lines(d.fields);
    for (std::string line; std::getline(lines, line);) {
      if (line.find('=') != std::string::npos) continue;  // a constant
      const auto space = line.find(' ');
      fields[line.substr(space + 1)] = line.substr(0, space);
    }
    return fields;
  }
  return {};
}

template <typename T>
std::string msgType() {
  if (std::is_same_v<T, std::uint64_t>) return "uint64";
  if (std::is_same_v<T, double>) return "float64";
  return "(no Status.msg type)";
}

TEST_CASE("status fields: SL_STATUS_ENGINE_FIELDS and the hand-written fields are Status.msg's") {
  // Status.msg fields that status_fields.h leaves to hand-written code.
  const std::set<std::string> by_hand = {
      "stamp", "state", "pattern", "sets_dropped", "writes_timed_out", "recording", "last_error",
      "patterns", "trigger", "cameras", "motion_compensation", "start_at", "requests_received",
      "requests_answered", "requests_rate_limited", "requests_invalid", "replies_timed_out",
      "degraded_reason", "last_error_stamp", "requests_malformed", "requests_rejected",
      "clouds_lost_to_readers", "points_readers", "images_not_compressed", "adaptive_mode",
      "adaptive_reason"};
  auto fields = statusMsgFields();
  REQUIRE(fields.size() > by_hand.size());
  std::map<std::string, std::string> listed;
#define SL_LIST_FIELD(type, name, label) listed[#name] = msgType<type>();
  SL_STATUS_ENGINE_FIELDS(SL_LIST_FIELD)
#undef SL_LIST_FIELD
  for (const auto& [name, type] : listed) {
    INFO("SL_STATUS_ENGINE_FIELDS has " << name << ": it must be a Status.msg field of that type");
    CHECK(fields.count(name) == 1);
    CHECK(fields[name] == type);
    CHECK(by_hand.count(name) == 0);
  }
  for (const auto& [name, type] : fields) {
    INFO("Status.msg field " << name
                             << ": add it to SL_STATUS_ENGINE_FIELDS (sl/client/status_fields.h), or, "
                                "if it is not the engine's, to the hand-written ones (and this list)");
    CHECK(listed.count(name) + by_hand.count(name) == 1);
  }
}

TEST_CASE("status fields: each of SL_STATUS_ENGINE_FIELDS goes from EngineStatus into the sample") {
  EngineStatus s;
  double next = 1;
#define SL_SET_FIELD(type, name, label) s.name = static_cast<type>(next++);
  SL_STATUS_ENGINE_FIELDS(SL_SET_FIELD)
#undef SL_SET_FIELD
  const msg::StatusMessage message(s, {}, msg::EdgeCounters{}, kStamp);
  const msg::Status& m = message.sample();
  next = 1;
#define SL_CHECK_FIELD(type, name, label) \
  CHECK(m.name == static_cast<type>(next)); \
  ++next;
  SL_STATUS_ENGINE_FIELDS(SL_CHECK_FIELD)
#undef SL_CHECK_FIELD
  CHECK(next > 10);
}

TEST_CASE("reply: every result code has its wire value and comes back as itself") {
  for (const auto& [ours, wire] : msg::kReplyCodes) {
    const msg::ReplyMessage message("client-1", 77, {ours, "why"}, {"p"}, "");
    CHECK(message.sample().code == wire);
    CHECK(message.sample().accepted == (ours == Code::kOk));
    CHECK(msg::fromReplyCode(message.sample().code) == ours);
    CHECK(str(message.sample().client_id) == "client-1");
    CHECK(message.sample().request_id == 77);
    CHECK(str(message.sample().reason) == "why");
    CHECK(strings(message.sample().patterns) == std::vector<std::string>{"p"});
  }
}

TEST_CASE("frame ids: dds.frame_id for the first camera, <id>_optical_frame for the others") {
  const FrameIds ids{"top", "sl_camera_optical_frame"};
  CHECK(ids.of("top") == "sl_camera_optical_frame");
  CHECK(ids.of("side") == "side_optical_frame");
  CHECK(ids.isFirst("top"));
  CHECK_FALSE(ids.isFirst("side"));
  CHECK_FALSE(ids.isFirst("sl_camera_optical_frame"));  // a camera id, not a frame id
}

namespace {

// Records what the dispatcher asks of the sensor.
struct FakeSensor : CommandTarget {
  std::vector<StartRequest> starts;
  int stops = 0;
  std::vector<std::string> selected;
  CommandResult start(const StartRequest& r) override {
    starts.push_back(r);
    return {};
  }
  CommandResult stop() override {
    ++stops;
    return {Code::kNotRunning, "not scanning"};
  }
  CommandResult selectPattern(const std::string& p) override {
    selected.push_back(p);
    return {};
  }
  std::vector<std::string> patterns() const override { return {"p1", "p2"}; }
  std::string configText() const override { return "sensor: sim\n"; }
};

// A request whose strings live in this object.
struct RequestSample {
  std::string client = "client-a", pattern, recording;
  std::vector<std::string> cameras;
  std::vector<char*> camera_pointers;
  msg::Request r{};
  explicit RequestSample(std::uint8_t command, std::uint64_t id = 1) {
    r.command = command;
    r.request_id = id;
  }
  const msg::Request& sample() {
    r.client_id = client.data();
    r.pattern = pattern.data();
    r.recording = recording.data();
    camera_pointers.clear();
    for (auto& c : cameras) camera_pointers.push_back(c.data());
    r.cameras._buffer = camera_pointers.data();
    r.cameras._length = r.cameras._maximum = static_cast<std::uint32_t>(camera_pointers.size());
    r.cameras._release = false;
    return r;
  }
};

constexpr std::int64_t kSecond = 1'000'000'000;
// Senders: the DDS participants that wrote the requests (RequestOrigins).
constexpr SenderId kSenderA = 0x1001, kSenderB = 0x2002;

}  // namespace

TEST_CASE("dispatch: a start's options reach the sensor; every reply lists the patterns") {
  FakeSensor sensor;
  RequestDispatcher dispatcher(RequestLimits{});
  RequestSample start(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START, 5);
  start.pattern = "p2";
  start.recording = "rec";
  start.cameras = {"top"};
  start.r.count = 3;
  start.r.trigger = sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_SOFTWARE;
  start.r.motion_compensation = sl_msgs_msg_dds__CommandRequest_Constants_MOTION_OFF;
  start.r.start_at = {1'700'000'000, 5};
  const auto reply = dispatcher.dispatch(start.sample(), kSenderA, sensor, kSecond);
  REQUIRE(reply);
  CHECK(reply->result.accepted());
  CHECK(reply->client_id == "client-a");
  CHECK(reply->request_id == 5);
  CHECK(reply->patterns == std::vector<std::string>{"p1", "p2"});
  CHECK(reply->detail.empty());
  REQUIRE(sensor.starts.size() == 1);
  const StartRequest& s = sensor.starts[0];
  CHECK(s.pattern == "p2");
  CHECK(s.recording == "rec");
  CHECK(s.count == 3);
  CHECK(s.trigger == TriggerMode::kSoftware);
  CHECK(s.motion_compensation == false);
  CHECK(s.start_at_ns == 1'700'000'000'000'000'005);
  CHECK(s.cameras == std::vector<std::string>{"top"});
  dispatcher.replied(true);
  dispatcher.replied(false);
  CHECK(dispatcher.counters().received == 1);
  CHECK(dispatcher.counters().answered == 1);
  CHECK(dispatcher.repliesTimedOut() == 1);

  RequestSample config(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_GET_CONFIG, 6);
  const auto config_reply = dispatcher.dispatch(config.sample(), kSenderA, sensor, kSecond);
  REQUIRE(config_reply);
  CHECK(config_reply->detail == "sensor: sim\n");
  RequestSample select(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN, 7);
  select.pattern = "p1";
  CHECK(dispatcher.dispatch(select.sample(), kSenderA, sensor, kSecond)->result.accepted());
  CHECK(sensor.selected == std::vector<std::string>{"p1"});
  RequestSample stop(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP, 8);
  CHECK(dispatcher.dispatch(stop.sample(), kSenderA, sensor, kSecond)->result.code == Code::kNotRunning);
  CHECK(sensor.stops == 1);
}

TEST_CASE("dispatch: bad values are refused before the sensor sees them; retries get the first answer") {
  FakeSensor sensor;
  RequestLimits limits;
  limits.max_string = 16;
  RequestDispatcher dispatcher(limits);

  RequestSample bad_enum(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START, 1);
  bad_enum.r.trigger = static_cast<std::uint8_t>(9);
  auto reply = dispatcher.dispatch(bad_enum.sample(), kSenderA, sensor, kSecond);
  CHECK(reply->result.code == Code::kInvalidOption);
  CHECK_THAT(reply->result.reason, Catch::Contains("unknown trigger mode 9"));

  RequestSample long_pattern(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN, 2);
  long_pattern.pattern = std::string(100, 'x');
  reply = dispatcher.dispatch(long_pattern.sample(), kSenderA, sensor, kSecond);
  CHECK(reply->result.code == Code::kInvalidOption);
  CHECK_THAT(reply->result.reason, Catch::Contains("pattern is 100 bytes"));
  CHECK(dispatcher.counters().invalid == 1);

  RequestSample unknown(static_cast<std::uint8_t>(17), 3);
  reply = dispatcher.dispatch(unknown.sample(), kSenderA, sensor, kSecond);
  CHECK(reply->result.code == Code::kInvalidCommand);
  CHECK_THAT(reply->result.reason, Catch::Contains("unknown command 17"));
  CHECK(sensor.starts.empty());
  CHECK(sensor.selected.empty());

  // A retry (same client, same id) of a start: answered again, started once.
  RequestSample start(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START, 4);
  CHECK(dispatcher.dispatch(start.sample(), kSenderA, sensor, kSecond)->result.accepted());
  CHECK(dispatcher.dispatch(start.sample(), kSenderA, sensor, kSecond)->result.accepted());
  CHECK(sensor.starts.size() == 1);
  start.client = "client-b";  // another client's request 4 is a new request
  CHECK(dispatcher.dispatch(start.sample(), kSenderA, sensor, kSecond)->result.accepted());
  CHECK(sensor.starts.size() == 2);
}

TEST_CASE("dispatch: over the rate limit a request is counted, not answered and not carried out") {
  FakeSensor sensor;
  RequestLimits limits;
  limits.rate_hz = 1;
  limits.burst = 3;
  RequestDispatcher dispatcher(limits);
  int answered = 0;
  for (std::uint64_t id = 1; id <= 5; ++id) {
    RequestSample select(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN, id);
    select.pattern = "p1";
    answered += dispatcher.dispatch(select.sample(), kSenderA, sensor, kSecond).has_value();
  }
  CHECK(answered == 3);
  CHECK(sensor.selected.size() == 3);
  CHECK(dispatcher.counters().received == 5);
  CHECK(dispatcher.counters().rate_limited == 2);
  // A second later one token is back.
  RequestSample later(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN, 6);
  CHECK(dispatcher.dispatch(later.sample(), kSenderA, sensor, 2 * kSecond + kSecond / 100).has_value());
}

// The identity probe of issue 36: 1,000 START/STOP/SET_PATTERN from 1,000
// client ids of one participant in 0.1 s left 703 unanswered and an honest
// client with a new id starved in the one allowance the ids shared. The
// allowance is the sender's (participant's) now: the flood spends its own.
TEST_CASE("dispatch: 1,000 made-up client ids of one sender share its allowance; another sender is served") {
  FakeSensor sensor;
  RequestLimits limits;  // 20/s, burst 40, 256 senders
  RequestDispatcher dispatcher(limits);
  int flood_answered = 0;
  for (int i = 0; i < 1000; ++i) {
    RequestSample select(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN, 1);
    select.client = "fake-" + std::to_string(i);
    select.pattern = "p1";
    flood_answered += dispatcher.dispatch(select.sample(), kSenderA, sensor, kSecond).has_value();
  }
  CHECK(flood_answered == static_cast<int>(limits.burst));
  CHECK(dispatcher.counters().rate_limited == 1000 - static_cast<std::uint64_t>(limits.burst));
  // An honest client of another participant, in the same instant.
  RequestSample stop(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP, 1);
  stop.client = "honest";
  const auto reply = dispatcher.dispatch(stop.sample(), kSenderB, sensor, kSecond);
  REQUIRE(reply);
  CHECK(reply->client_id == "honest");
  CHECK(sensor.stops == 1);
  // Every request answered or counted.
  for (int i = 0; i < flood_answered + 1; ++i) dispatcher.replied(true);
  const RequestCounters& c = dispatcher.counters();
  CHECK(c.received == 1001);
  CHECK(c.answered + c.rate_limited == c.received);
  // The flooding participant gets tokens back at its rate, like anyone.
  RequestSample later(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS, 2);
  CHECK(dispatcher.dispatch(later.sample(), kSenderA, sensor, kSecond + kSecond / 10).has_value());
}

TEST_CASE("dispatch: another sender reusing a client's id and request id is not taken for its retry") {
  FakeSensor sensor;
  RequestDispatcher dispatcher(RequestLimits{});
  RequestSample start(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START, 9);
  start.client = "operator";
  CHECK(dispatcher.dispatch(start.sample(), kSenderA, sensor, kSecond)->result.accepted());
  // The same (client, id) from another participant is a request of its own.
  CHECK(dispatcher.dispatch(start.sample(), kSenderB, sensor, kSecond)->result.accepted());
  CHECK(sensor.starts.size() == 2);
  // The first participant's retry is answered from memory, not started again.
  CHECK(dispatcher.dispatch(start.sample(), kSenderA, sensor, kSecond)->result.accepted());
  CHECK(sensor.starts.size() == 2);
}

// A START with 100,000 camera ids is refused on its count alone: the entries
// are never read (here they do not even exist), so the refusal costs the same
// whatever the list holds.
TEST_CASE("dispatch: an oversized camera list is refused without reading its entries") {
  FakeSensor sensor;
  RequestDispatcher dispatcher(RequestLimits{});
  RequestSample start(sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START, 1);
  msg::Request request = start.sample();
  request.cameras._length = request.cameras._maximum = 100'000;
  request.cameras._buffer = nullptr;  // reading an entry would crash
  const auto reply = dispatcher.dispatch(request, kSenderA, sensor, kSecond);
  REQUIRE(reply);
  CHECK(reply->result.code == Code::kInvalidOption);
  CHECK_THAT(reply->result.reason, Catch::Contains("cameras has 100000 entries, more than 16"));
  CHECK(sensor.starts.empty());
}

TEST_CASE("velocityOf: a TwistStamped as the adaptive policy takes it", "[adaptive]") {
  geometry_msgs_msg_dds__TwistStamped_ m{};
  m.header.frame_id = const_cast<char*>("sl_camera_optical_frame");
  m.twist.linear = {0.06, -0.01, 0.002};
  m.twist.angular = {0.0, 0.1, -0.2};
  const auto v = sl::daemon::velocityOf(m, "", 42);
  REQUIRE(v);
  CHECK(v->received_ns == 42);
  CHECK(v->linear_m_s == std::array<double, 3>{0.06, -0.01, 0.002});
  CHECK(v->angular_rad_s == std::array<double, 3>{0.0, 0.1, -0.2});
  // adaptive.frame_id: another frame is ignored, the same one taken.
  CHECK(sl::daemon::velocityOf(m, "sl_camera_optical_frame", 1));
  CHECK_FALSE(sl::daemon::velocityOf(m, "base_link", 1));
  m.header.frame_id = nullptr;
  CHECK_FALSE(sl::daemon::velocityOf(m, "base_link", 1));
  CHECK(sl::daemon::velocityOf(m, "", 1));
  // Not finite: ignored.
  m.twist.angular.z = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(sl::daemon::velocityOf(m, "", 1));
}
