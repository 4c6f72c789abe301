// AravisCamera through the real GigE Vision path, without hardware: Aravis'
// fake GigE Vision camera runs in this process on 127.0.0.1 and is filled
// with images rendered by the simulated sensor; the driver opens it by its
// address (GVCP and GVSP over loopback only, no discovery broadcast) and the
// frames it delivers are decoded and triangulated like the daemon does.
//
// Frame delivery is deterministic: the fake camera runs in software-trigger
// mode and sends one frame per trigger, filled with the oldest queued image;
// the test queues image k, triggers, and grabs frame k before queueing the
// next, so frame k is pattern image k. Every grab has a timeout, so a lost
// frame fails the test instead of hanging it.
#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "sl/daemon/config.h"
#include "sl/daemon/devices.h"
#include "sl/drivers/aravis_camera.h"
#include "sl/drivers/aravis_fake_camera.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/triangulator.h"

using namespace std::chrono_literals;
using sl::drivers::AravisCamera;
using sl::drivers::AravisCameraConfig;
using sl::drivers::AravisTriggerConfig;
using sl::drivers::FakeGigeCamera;
using sl::drivers::FakeGigeOptions;

namespace {

constexpr const char* kLoopback = "127.0.0.1";

FakeGigeOptions fakeOptions() {
  FakeGigeOptions o;
  o.interface_address = kLoopback;
  o.serial = "SL-TEST-1";
  return o;
}

// The camera settings for the loopback fake camera: software trigger, device
// timestamps, no packet socket, automatic socket buffer, large packets.
AravisCameraConfig loopbackConfig(const std::string& pixel_format = "Mono8") {
  AravisCameraConfig c;
  c.name = "top";
  c.device = kLoopback;
  c.width = 1440;
  c.height = 1080;
  c.pixel_format = pixel_format;
  c.exposure_us = 5000;
  c.gain = 0;
  c.trigger.mode = AravisTriggerConfig::Mode::kSoftware;
  c.timestamp = AravisCameraConfig::Timestamp::kDevice;
  c.packet_size = 8972;  // a jumbo-frame payload; loopback carries it in one datagram
  c.packet_socket = false;
  c.socket_buffer_bytes = 0;
  c.buffer_count = 8;
  // The fake camera sends from a thread of this process; on a loaded machine
  // it can pause between packets for longer than Aravis' default 100 ms.
  c.frame_retention_ms = 2000;
  c.reconnect_interval_s = 0.5;
  return c;
}

const sl::daemon::DaemonConfig& simConfig() {
  static const sl::daemon::DaemonConfig config =
      sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  return config;
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int y = 0; y < a.rows; ++y)
    if (std::memcmp(a.ptr(y), b.ptr(y), a.cols * a.elemSize()) != 0) return false;
  return true;
}

std::optional<sl::pipeline::Frame> grabWithin(AravisCamera& camera, std::chrono::milliseconds limit) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < deadline) {
    if (auto frame = camera.grab(100ms)) return frame;
  }
  return std::nullopt;
}

// Sends `image` with device timestamp `stamp` and grabs it. The fake camera
// never resends lost packets, and on a loaded machine the first frame after
// AcquisitionStart occasionally times out in the receiver (observed about once
// in six runs on 2 busy cores); such a frame is counted by the driver and sent
// again, so frame k is still image k. Returns nullopt after 3 attempts.
std::optional<sl::pipeline::Frame> sendAndGrab(FakeGigeCamera& fake, AravisCamera& camera,
                                               const cv::Mat& image, std::uint64_t stamp,
                                               bool trigger_over_gvcp, int& resent) {
  for (int attempt = 0; attempt < 3; ++attempt) {
    if (attempt > 0) ++resent;
    fake.queue(image, stamp);
    if (trigger_over_gvcp) camera.triggerSoftware();
    else fake.trigger();
    if (auto frame = grabWithin(camera, 4000ms)) return frame;
  }
  return std::nullopt;
}

// Renders every image of `pattern`, sends each through the fake camera and
// grabs it; returns the received frames.
std::vector<sl::pipeline::Frame> sendPattern(const sl::drivers::SimulatedSensor& sim,
                                             FakeGigeCamera& fake, AravisCamera& camera,
                                             const sl::pipeline::PatternSpec& pattern,
                                             std::vector<cv::Mat>& rendered, int& resent) {
  std::vector<sl::pipeline::Frame> frames;
  for (int k = 0; k < pattern.frameCount(); ++k) {
    rendered.push_back(sim.render(pattern.name, k, 1000 + k));
    const std::uint64_t stamp = 1'700'000'000'000'000'000ull + 33'333'333ull * k;
    // Even frames: TriggerSoftware over GVCP from the driver; odd frames: the
    // in-process trigger (what the daemon's fake sensor uses as trigger line).
    auto frame = sendAndGrab(fake, camera, rendered.back(), stamp, k % 2 == 0, resent);
    INFO("frame " << k << " of " << pattern.name << "; fake sent " << fake.counters().frames_sent
                  << "; camera delivered " << camera.counters().frames_delivered
                  << ", incomplete " << camera.counters().buffers_incomplete << ", timed out "
                  << camera.counters().buffers_timed_out);
    REQUIRE(frame);
    CHECK(static_cast<std::uint64_t>(frame->stamp_ns) == stamp);
    frames.push_back(std::move(*frame));
  }
  return frames;
}

}  // namespace

TEST_CASE("packed and unpacked mono formats decode to the pixel values", "[aravis][pixels]") {
  using sl::drivers::decodeMonoImage;
  using sl::drivers::monoPixelFormatCode;
  const std::vector<std::uint16_t> p12 = {0xABC, 0x123, 0xFFF, 0x000};
  const std::vector<std::uint16_t> p10 = {0x2BC, 0x123, 0x3FF, 0x001};
  auto check = [](const cv::Mat& m, const std::vector<std::uint16_t>& expected) {
    REQUIRE(m.type() == CV_16UC1);
    REQUIRE(m.total() == expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i)
      CHECK(m.at<std::uint16_t>(0, static_cast<int>(i)) == expected[i]);
  };
  // GigE Vision Mono12Packed: [P0 hi8][P1 lo4 | P0 lo4][P1 hi8].
  const std::uint8_t gv12[] = {0xAB, 0x3C, 0x12, 0xFF, 0x0F, 0x00};
  check(decodeMonoImage(gv12, sizeof gv12, 4, 1, monoPixelFormatCode("Mono12Packed")), p12);
  // GigE Vision Mono10Packed: [P0 hi8][P1 lo2 << 4 | P0 lo2][P1 hi8].
  const std::uint8_t gv10[] = {0xAF, 0x30, 0x48, 0xFF, 0x13, 0x00};
  check(decodeMonoImage(gv10, sizeof gv10, 4, 1, monoPixelFormatCode("Mono10Packed")), p10);
  // PFNC Mono12p: little-endian bit stream, 12 bits per pixel.
  const std::uint8_t pf12[] = {0xBC, 0x3A, 0x12, 0xFF, 0x0F, 0x00};
  check(decodeMonoImage(pf12, sizeof pf12, 4, 1, monoPixelFormatCode("Mono12p")), p12);
  // PFNC Mono10p: 4 pixels in 5 bytes.
  std::uint64_t bits = 0;
  for (int i = 0; i < 4; ++i) bits |= std::uint64_t(p10[i]) << (10 * i);
  std::uint8_t pf10[5];
  for (int i = 0; i < 5; ++i) pf10[i] = static_cast<std::uint8_t>(bits >> (8 * i));
  check(decodeMonoImage(pf10, sizeof pf10, 4, 1, monoPixelFormatCode("Mono10p")), p10);
  // Unpacked 16-bit containers, little endian.
  const std::uint8_t le[] = {0xBC, 0x0A, 0x23, 0x01, 0xFF, 0x0F, 0x00, 0x00};
  check(decodeMonoImage(le, sizeof le, 4, 1, monoPixelFormatCode("Mono12")), p12);
  check(decodeMonoImage(le, sizeof le, 4, 1, monoPixelFormatCode("Mono16")), p12);
  // Mono8 copies; short buffers and unknown formats give an empty image.
  const std::uint8_t m8[] = {1, 2, 3, 4};
  const cv::Mat mono8 = decodeMonoImage(m8, sizeof m8, 2, 2, monoPixelFormatCode("Mono8"));
  REQUIRE(mono8.type() == CV_8UC1);
  CHECK(mono8.at<std::uint8_t>(1, 1) == 4);
  CHECK(decodeMonoImage(gv12, 5, 4, 1, monoPixelFormatCode("Mono12Packed")).empty());
  CHECK(decodeMonoImage(m8, sizeof m8, 2, 2, 0x02180014u /* RGB8 */).empty());
  CHECK(sl::drivers::monoBitDepth(monoPixelFormatCode("Mono10p")) == 10);
  CHECK(monoPixelFormatCode("Mono14") == 0);
}

TEST_CASE("fake GigE camera: simulated images arrive bit-identical and give the identical cloud",
          "[aravis][fake][pipeline]") {
  const auto& config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  FakeGigeCamera fake(fakeOptions());
  const auto camera = AravisCamera::open(loopbackConfig());
  CHECK(camera->width() == 1440);
  CHECK(camera->height() == 1080);
  CHECK(camera->deviceId() == kLoopback);
  // The fake camera has no gamma, LUT, auto exposure or black level: noted, not errors.
  bool gamma_noted = false;
  for (const auto& note : camera->notes()) gamma_noted |= note.find("Gamma") != std::string::npos;
  CHECK(gamma_noted);
  camera->start();

  const sl::pipeline::PatternSpec& pattern = config.patterns.front();
  std::vector<cv::Mat> rendered;
  int resent = 0;
  const auto frames = sendPattern(*sim, fake, *camera, pattern, rendered, resent);
  std::vector<cv::Mat> received;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    INFO("frame " << k);
    CHECK(frames[k].bit_depth == 8);
    CHECK(identical(frames[k].image, rendered[k]));
    received.push_back(frames[k].image);
  }
  const auto counters = camera->counters();
  CHECK(counters.frames_delivered == frames.size());
  CHECK(counters.buffers_incomplete + counters.buffers_timed_out == static_cast<std::uint64_t>(resent));
  CHECK(resent <= 2);
  CHECK(fake.counters().frames_sent == frames.size() + resent);

  // Decode + triangulate both image sets like the daemon's processing stage
  // (sl::pipeline::Decoder of the pattern's spec, Triangulator).
  const sl::pipeline::Decoder decoder(pattern, config.decoder);
  const sl::pipeline::Triangulator triangulator(config.calibration, config.triangulator);
  const auto direct = triangulator.triangulate(decoder.decode(rendered, 8));
  const auto over_gige = triangulator.triangulate(decoder.decode(received, frames[0].bit_depth));
  REQUIRE(direct.points.size() == over_gige.points.size());
  REQUIRE(direct.width == 1440);
  // Identical images through a deterministic pipeline: the clouds must be
  // bit-identical (NaNs included), so the comparison is exact.
  CHECK(std::memcmp(direct.points.data(), over_gige.points.data(),
                    direct.points.size() * sizeof(sl::pipeline::PointXYZI)) == 0);
  const std::size_t valid = direct.validCount();
  CHECK(valid == over_gige.validCount());
  CHECK(valid > direct.points.size() / 2);  // the scene fills most of the view
  WARN("fake GigE cloud: " << over_gige.validCount() << " of " << over_gige.points.size()
                           << " points valid, identical to the direct cloud");
  camera->stop();
}

TEST_CASE("fake GigE camera: Mono16 frames arrive as CV_16UC1, identical", "[aravis][fake]") {
  auto sim_config = simConfig().sim;
  sim_config.bit_depth = 12;
  const auto sim = sl::drivers::SimulatedSensor::create(sim_config);
  FakeGigeCamera fake(fakeOptions());
  const auto camera = AravisCamera::open(loopbackConfig("Mono16"));
  camera->start();
  std::vector<cv::Mat> rendered;
  int resent = 0;
  const auto frames = sendPattern(*sim, fake, *camera, simConfig().patterns.front(), rendered, resent);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    INFO("frame " << k);
    CHECK(frames[k].image.type() == CV_16UC1);
    CHECK(frames[k].bit_depth == 16);
    CHECK(identical(frames[k].image, rendered[k]));
  }
}

TEST_CASE("configuration errors name the camera and the feature", "[aravis][fake][config]") {
  FakeGigeCamera fake(fakeOptions());
  auto config = loopbackConfig();
  SECTION("a pixel format the camera rejects") {
    config.pixel_format = "Mono12";  // the fake camera offers Mono8 and Mono16 only
    REQUIRE_THROWS_WITH(AravisCamera::open(config),
                        Catch::Contains("camera 'top'") && Catch::Contains("PixelFormat Mono12"));
  }
  SECTION("a region larger than the sensor") {
    config.width = 4096;
    REQUIRE_THROWS_WITH(AravisCamera::open(config), Catch::Contains("region"));
  }
  SECTION("a trigger line the camera does not have") {
    config.trigger.mode = AravisTriggerConfig::Mode::kHardware;
    config.trigger.line = "Line7";
    REQUIRE_THROWS_WITH(AravisCamera::open(config),
                        Catch::Contains("TriggerSource") && Catch::Contains("Line7"));
  }
  SECTION("an unsupported pixel format is refused before opening") {
    config.pixel_format = "BayerRG8";
    REQUIRE_THROWS_AS(AravisCamera::open(config), std::invalid_argument);
  }
  SECTION("hardware trigger on Line0, rising edge, is accepted") {
    config.trigger.mode = AravisTriggerConfig::Mode::kHardware;
    config.trigger.line = "Line0";
    REQUIRE_NOTHROW(AravisCamera::open(config));
  }
}

TEST_CASE("fake GigE camera: incomplete frames are counted, never delivered",
          "[aravis][fake][robust]") {
  const auto sim = sl::drivers::SimulatedSensor::create(simConfig().sim);
  FakeGigeCamera fake(fakeOptions());
  auto config = loopbackConfig();
  config.frame_retention_ms = 300;  // lost packets are never resent by the fake camera
  const auto camera = AravisCamera::open(config);
  camera->start();
  const cv::Mat lossy = sim->render(simConfig().patterns.front().name, 0, 7);
  const cv::Mat clean = sim->render(simConfig().patterns.front().name, 1, 8);
  fake.setLostPacketRatio(0.05);  // ~9 of the ~175 packets of each frame lost
  constexpr int kLossy = 6;
  for (int k = 0; k < kLossy; ++k) {
    fake.push(lossy, 1000 + k);
    std::this_thread::sleep_for(20ms);  // let the fake camera send it before the loss ratio changes
  }
  std::this_thread::sleep_for(200ms);
  fake.setLostPacketRatio(0);
  // A clean frame after the lossy ones: the stream closes any frame still
  // waiting for packets, and this one must arrive intact.
  fake.push(clean, 2000);
  std::optional<sl::pipeline::Frame> last;
  const auto deadline = std::chrono::steady_clock::now() + 15s;
  while (std::chrono::steady_clock::now() < deadline) {
    if (auto frame = camera->grab(100ms)) {
      // Any frame delivered is complete: the lossy image (resent in full) or the clean one.
      CHECK((identical(frame->image, lossy) || identical(frame->image, clean)));
      last = std::move(frame);
    }
    const auto c = camera->counters();
    if (c.frames_delivered + c.buffers_incomplete + c.buffers_timed_out >= kLossy + 1) break;
  }
  const auto c = camera->counters();
  INFO("delivered " << c.frames_delivered << ", incomplete " << c.buffers_incomplete
                    << ", timed out " << c.buffers_timed_out);
  CHECK(c.frames_delivered + c.buffers_incomplete + c.buffers_timed_out == kLossy + 1);
  CHECK(c.buffers_incomplete + c.buffers_timed_out > 0);
  REQUIRE(last);
  CHECK(identical(last->image, clean));
  CHECK(static_cast<std::uint64_t>(last->stamp_ns) == 2000);
}

TEST_CASE("fake GigE camera: a camera that disappears is reported and reopened when it returns",
          "[aravis][fake][robust]") {
  const auto sim = sl::drivers::SimulatedSensor::create(simConfig().sim);
  auto fake = std::make_unique<FakeGigeCamera>(fakeOptions());
  const auto camera = AravisCamera::open(loopbackConfig());
  camera->start();
  const cv::Mat image = sim->render(simConfig().patterns.front().name, 1, 9);
  int resent = 0;
  REQUIRE(sendAndGrab(*fake, *camera, image, 1, false, resent));

  fake.reset();  // the camera is gone: GVCP heartbeats go unanswered
  std::string error;
  const auto lost_deadline = std::chrono::steady_clock::now() + 25s;
  while (error.empty() && std::chrono::steady_clock::now() < lost_deadline) {
    try {
      camera->grab(100ms);
    } catch (const std::runtime_error& e) {
      error = e.what();
    }
  }
  INFO(error);
  REQUIRE_THAT(error, Catch::Contains("camera 'top'") && Catch::Contains("connection lost"));
  CHECK_FALSE(camera->counters().connected);

  fake = std::make_unique<FakeGigeCamera>(fakeOptions());  // it returns
  std::optional<sl::pipeline::Frame> frame;
  const auto back_deadline = std::chrono::steady_clock::now() + 20s;
  while (!frame && std::chrono::steady_clock::now() < back_deadline) {
    fake->push(image, 2);
    try {
      frame = camera->grab(200ms);
    } catch (const std::runtime_error&) {
      // a reconnect attempt that failed while the camera was starting up
    }
  }
  REQUIRE(frame);
  CHECK(identical(frame->image, image));
  const auto c = camera->counters();
  CHECK(c.connected);
  CHECK(c.connection_losses == 1);
  CHECK(c.reconnects == 1);
}

TEST_CASE("config: the fake GigE sensor file loads; camera keys are checked", "[aravis][config]") {
  const auto config =
      sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/fake-gige.yaml");
  CHECK(config.sensor == sl::daemon::SensorKind::kFakeGige);
  REQUIRE(config.aravis.cameras.size() == 1);
  const auto& c = config.aravis.cameras.front();
  CHECK(c.device == "127.0.0.1");
  CHECK(c.width == 1440);
  CHECK(c.trigger.mode == AravisTriggerConfig::Mode::kSoftware);
  CHECK(c.timestamp == AravisCameraConfig::Timestamp::kDevice);
  CHECK_FALSE(c.packet_socket);
  CHECK(config.aravis.fake.serial == "SL-FAKE-TOP");

  std::ifstream in(std::string(SL_SOURCE_DIR) + "/config/fake-gige.yaml");
  std::stringstream text;
  text << in.rdbuf();
  auto with = [&](const std::string& from, const std::string& to) {
    std::string s = text.str();
    const auto at = s.find(from);
    REQUIRE(at != std::string::npos);
    return s.replace(at, from.size(), to);
  };
  CHECK_THROWS_WITH(sl::daemon::parseConfig(with("    buffers: 16", "    bufers: 16"), "fg.yaml"),
                    Catch::Contains("fg.yaml:") && Catch::Contains("cameras") &&
                        Catch::Contains("bufers"));
  CHECK_THROWS_WITH(
      sl::daemon::parseConfig(with("pixel_format: Mono8", "pixel_format: Mono14"), "fg.yaml"),
      Catch::Contains("pixel_format") && Catch::Contains("Mono14"));
  CHECK_THROWS_WITH(
      sl::daemon::parseConfig(with("trigger: {mode: software}", "trigger: {mode: sometimes}"),
                              "fg.yaml"),
      Catch::Contains("trigger.mode"));
  CHECK_THROWS_WITH(
      sl::daemon::parseConfig(with("trigger: {mode: software}", "trigger: {mode: hardware}"),
                              "fg.yaml"),
      Catch::Contains("software"));
}

TEST_CASE("software trigger: one frame per TriggerSoftware, none without",
          "[aravis][fake][trigger]") {
  const auto sim = sl::drivers::SimulatedSensor::create(simConfig().sim);
  FakeGigeCamera fake(fakeOptions());
  const std::shared_ptr<sl::drivers::Camera> camera = AravisCamera::open(loopbackConfig());
  auto& aravis = static_cast<AravisCamera&>(*camera);
  REQUIRE(camera->hasSoftwareTrigger());
  CHECK_THROWS_WITH(camera->triggerSoftware(),
                    Catch::Contains("camera 'top'") && Catch::Contains("before start()"));
  camera->start();

  // An image waits in the camera until a trigger asks for it.
  const std::string& pattern = simConfig().patterns.front().name;
  fake.queue(sim->render(pattern, 0, 1), 100);
  CHECK_FALSE(grabWithin(aravis, 300ms));
  CHECK(fake.counters().frames_sent == 0);
  camera->triggerSoftware();
  auto first = grabWithin(aravis, 4000ms);
  int resent = 0;
  if (!first) {  // lost in the receiver (see sendAndGrab): send the image again
    ++resent;
    first = sendAndGrab(fake, aravis, sim->render(pattern, 0, 1), 100, true, resent);
  }
  REQUIRE(first);
  CHECK(first->stamp_ns == 100);

  // Each trigger gives exactly one frame: nothing more arrives after it.
  constexpr int kTriggers = 3;
  for (int k = 1; k <= kTriggers; ++k) {
    const cv::Mat image = sim->render(pattern, k, 1 + k);
    auto frame = sendAndGrab(fake, aravis, image, 100 + k, true, resent);
    INFO("trigger " << k);
    REQUIRE(frame);
    CHECK(identical(frame->image, image));
    CHECK(frame->stamp_ns == 100 + k);
    CHECK_FALSE(camera->grab(150ms));
  }
  const auto c = aravis.counters();
  INFO("resent " << resent << ", incomplete " << c.buffers_incomplete << ", timed out "
                 << c.buffers_timed_out);
  CHECK(c.frames_delivered == 1 + kTriggers);
  CHECK(c.buffers_incomplete + c.buffers_timed_out == static_cast<std::uint64_t>(resent));
  CHECK(fake.counters().frames_sent == 1 + kTriggers + static_cast<std::uint64_t>(resent));
  CHECK(fake.counters().frames_unfilled == 0);  // no trigger without an image of ours
  camera->stop();
}

TEST_CASE("software trigger: a line-triggered camera refuses it, naming the camera and the line",
          "[aravis][fake][trigger]") {
  FakeGigeCamera fake(fakeOptions());
  auto config = loopbackConfig();
  config.trigger.mode = AravisTriggerConfig::Mode::kHardware;
  config.trigger.line = "Line0";
  const std::shared_ptr<sl::drivers::Camera> camera = AravisCamera::open(config);
  CHECK_FALSE(camera->hasSoftwareTrigger());
  CHECK_THROWS_AS(camera->triggerSoftware(), std::logic_error);
  CHECK_THROWS_WITH(camera->triggerSoftware(), Catch::Contains("camera 'top' (127.0.0.1)") &&
                                                   Catch::Contains("TriggerSoftware") &&
                                                   Catch::Contains("TriggerSource Line0") &&
                                                   Catch::Contains("mode: software"));
}

TEST_CASE(
    "fake GigE sensor: software triggering through the daemon's devices gives pattern i per "
    "trigger",
    "[aravis][fake][trigger]") {
  // As the daemon's software-trigger loop drives them: hold pattern i, trigger,
  // grab one frame. Frame i must be the render of pattern i (nearest of all).
  const auto config = sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/fake-gige.yaml");
  std::shared_ptr<void> keep_alive;
  const sl::daemon::EngineDevices devices = sl::daemon::openDevices(config, keep_alive);
  REQUIRE(devices.cameras.size() == 1);
  auto& camera = *devices.cameras.front();
  auto& projector = *devices.projector;
  REQUIRE(camera.hasSoftwareTrigger());
  REQUIRE(projector.canProjectSingle());
  const sl::pipeline::PatternSpec& pattern = config.patterns.front();
  const auto reference = sl::drivers::SimulatedSensor::create(config.sim);
  std::vector<cv::Mat> renders;
  for (int j = 0; j < pattern.frameCount(); ++j)
    renders.push_back(reference->render(pattern.name, j, 99));
  projector.select(pattern.name);
  camera.start();
  int retriggered = 0;
  for (int i = 0; i < pattern.frameCount(); ++i) {
    projector.projectSingle(i);
    const auto shown = std::chrono::system_clock::now().time_since_epoch();
    // A frame lost in the receiver (see sendAndGrab) is dropped after the
    // config's 500 ms frame retention; the trigger is then repeated.
    std::optional<sl::pipeline::Frame> frame;
    for (int attempt = 0; attempt < 3 && !frame; ++attempt) {
      if (attempt > 0) ++retriggered;
      camera.triggerSoftware();
      const auto deadline = std::chrono::steady_clock::now() + 2500ms;
      while (!frame && std::chrono::steady_clock::now() < deadline) frame = camera.grab(100ms);
    }
    INFO("pattern " << i);
    REQUIRE(frame);
    CHECK(frame->stamp_ns >= std::chrono::duration_cast<std::chrono::nanoseconds>(shown).count());
    int nearest = -1;
    double best = 0;
    for (int j = 0; j < pattern.frameCount(); ++j) {
      const double d = cv::norm(frame->image, renders[static_cast<std::size_t>(j)], cv::NORM_L2);
      if (nearest < 0 || d < best) {
        nearest = j;
        best = d;
      }
    }
    CHECK(nearest == i);
    CHECK_FALSE(camera.grab(100ms));  // one frame per trigger
  }
  CHECK(retriggered <= 2);
  projector.stop();
  camera.stop();
}
