// The scan engine's stages without its threads: start-request validation (a
// pure function), set processing (errors as values) and its reloads, device
// health, the stage threads' memory prefault.
#include <sys/mman.h>
#include <sys/resource.h>

#include <catch2/catch.hpp>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/device_health.h"
#include "engine/memory_prefault.h"
#include "engine/set_processor.h"
#include "engine/stage_latency.h"
#include "engine/start_validation.h"
#include "sl/daemon/config.h"
#include "sl/dds/dds.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/scan_processor.h"

using sl::client::CommandResult;
using sl::client::ScanState;
using sl::client::StartRequest;
using sl::client::TriggerMode;
using Code = CommandResult::Code;

namespace {

const sl::daemon::DaemonConfig& simConfig() {
  static const auto config = sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  return config;
}

constexpr sl::pipeline::TimestampNs kNow = 1'800'000'000'000'000'000;

struct Context {
  std::map<std::string, std::vector<std::string>> pattern_cameras;
  sl::daemon::StartContext context;
  Context() {
    for (const auto& p : simConfig().patterns) pattern_cameras[p.name] = {"top"};
    context.config = &simConfig();
    context.current_pattern = simConfig().runtime.default_pattern;
    context.pattern_cameras = &pattern_cameras;
    context.camera_ids = {"top", "side"};
    context.now_ns = kNow;
  }
};

void rejected(const StartRequest& request, const sl::daemon::StartContext& context, Code code,
              const std::string& words) {
  const auto v = sl::daemon::validateStart(request, context);
  INFO("reason: " << v.rejection.reason);
  CHECK_FALSE(v.accepted());
  CHECK(v.rejection.code == code);
  CHECK(v.rejection.reason.find(words) != std::string::npos);
}

}  // namespace

TEST_CASE("start validation: every option checked, with a code and a reason naming it") {
  Context c;
  StartRequest r;
  r.pattern = "nope";
  rejected(r, c.context, Code::kUnknownPattern, "unknown pattern 'nope'");
  r = {};
  r.count = -3;
  rejected(r, c.context, Code::kInvalidCount, "count must be >= 0");
  r = {};
  r.delay_s = 3601;
  rejected(r, c.context, Code::kInvalidOption, "delay must be 0..3600 s");
  r.delay_s = std::nan("");
  rejected(r, c.context, Code::kInvalidOption, "delay must be 0..3600 s");
  r = {};
  r.delay_s = 1;
  r.start_at_ns = kNow + 5;
  rejected(r, c.context, Code::kInvalidOption, "not both");
  r.delay_s = 0;
  r.start_at_ns = kNow - 2'000'000'000;
  rejected(r, c.context, Code::kInvalidOption, "2000 ms in the past");
  r.start_at_ns = kNow + 3601'000'000'000;
  rejected(r, c.context, Code::kInvalidOption, "more than 3600 s ahead");
  r = {};
  r.cameras = {"top", "top"};
  rejected(r, c.context, Code::kInvalidOption, "camera 'top' given twice");
  r.cameras = {"side"};
  rejected(r, c.context, Code::kInvalidOption, "camera 'side' does not triangulate");
  r.cameras = {"ghost"};
  rejected(r, c.context, Code::kInvalidOption, "unknown camera 'ghost'");
  r = {};
  r.recording = "../etc";
  rejected(r, c.context, Code::kInvalidCommand, "no paths");
  r = {};
  r.trigger = TriggerMode::kSoftware;
  c.context.software_unsupported = "camera 'top' has no software trigger";
  rejected(r, c.context, Code::kUnsupported, "software trigger: camera 'top'");
  c.context.software_unsupported.clear();
  c.context.state = ScanState::kScanning;
  c.context.scans_done = 2;
  c.context.scans_requested = 5;
  rejected(StartRequest{}, c.context, Code::kBusy, "already scanning '3+3_horizontal' (2 of 5)");
  c.context.state = ScanState::kWaiting;
  rejected(StartRequest{}, c.context, Code::kBusy, "waiting to scan");
}

TEST_CASE("start validation: an accepted start carries what to do") {
  Context c;
  StartRequest r;
  r.pattern = "3+3_both";
  r.count = 4;
  r.delay_s = 0.25;
  r.recording = "run-1.a";
  r.cameras = {"top"};
  r.motion_compensation = true;
  const auto v = sl::daemon::validateStart(r, c.context);
  REQUIRE(v.accepted());
  CHECK(v.start.pattern == "3+3_both");
  CHECK(v.start.count == 4);
  CHECK(v.start.trigger == simConfig().runtime.trigger);
  CHECK(v.start.launch_at_ns == kNow + 250'000'000);
  CHECK(v.start.recording_dir == simConfig().runtime.recording_root + "/run-1.a");
  CHECK(v.start.options.cameras_pattern == "3+3_both");
  CHECK(v.start.options.cameras == std::vector<std::string>{"top"});
  CHECK(v.start.options.motion_compensation == true);
  // Defaults: the current pattern, at once, no recording.
  const auto d = sl::daemon::validateStart(StartRequest{}, c.context);
  REQUIRE(d.accepted());
  CHECK(d.start.pattern == simConfig().runtime.default_pattern);
  CHECK(d.start.launch_at_ns == kNow);
  CHECK(d.start.recording_dir.empty());
  // A start time within the last second is taken (clocks of client and sensor differ a little).
  r = {};
  r.start_at_ns = kNow - 500'000'000;
  CHECK(sl::daemon::validateStart(r, c.context).accepted());
}

TEST_CASE("set processing: a simulated sequence gives a cloud per camera; faults are values") {
  const auto& config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  const std::string id = sim->camera()->id();
  const std::string pattern = "3+3_horizontal";
  const int n = config.findPattern(pattern)->frameCount();
  sl::pipeline::ImageSet set;
  set.pattern_name = pattern;
  set.sequence_id = 7;
  set.trigger_stamp_ns = kNow;
  sl::pipeline::CameraImages images;
  images.camera_id = id;
  images.bit_depth = 8;
  for (int i = 0; i < n; ++i) {
    images.frames.push_back(sim->render(pattern, i, 42 + i));
    images.stamps_ns.push_back(kNow + i * config.synchroniser.image_interval_ns);
  }
  set.cameras.push_back(images);

  sl::daemon::ProcessingConfig processing = sl::daemon::processingConfigOf(config, {id});
  REQUIRE(processing.calibrations.count(id) == 1);
  for (const bool keep_maps : {false, true}) {
    processing.keep_maps = keep_maps;
    sl::daemon::SetProcessor processor(processing);
    const sl::daemon::SetOutcome out = processor.process(set, {id}, false);
    INFO("error: " << out.error);
    REQUIRE(out.ok());
    REQUIRE(out.scans.size() == 1);
    const sl::daemon::CameraScan& scan = out.scans[0];
    CHECK(scan.camera_id == id);
    CHECK(scan.bit_depth == 8);
    CHECK((scan.maps != nullptr) == keep_maps);
    REQUIRE(scan.cloud);
    CHECK(scan.cloud->frame_id == id);  // the DDS edge maps it to a ROS frame id
    CHECK(scan.cloud->stamp_ns == kNow);
    std::size_t valid = 0;
    for (const auto& p : scan.cloud->points) valid += std::isfinite(p.z);
    CHECK(valid > scan.cloud->points.size() / 2);
    // The warm-up at construction (black frames through the same buffers)
    // leaves nothing behind: the first cloud is bit for bit that of a
    // processor that never saw them.
    const sl::pipeline::Decoder decoder(*config.findPattern(pattern), processing.decoder);
    const sl::pipeline::Triangulator triangulator(processing.calibrations.at(id), processing.triangulator);
    sl::pipeline::ScanProcessor fresh;
    const auto expected = fresh.process(decoder.codec(), triangulator, images, kNow, id).cloud;
    REQUIRE(expected->points.size() == scan.cloud->points.size());
    CHECK(std::memcmp(expected->points.data(), scan.cloud->points.data(),
                      expected->points.size() * sizeof(expected->points[0])) == 0);
  }

  sl::daemon::SetProcessor processor(processing);
  auto out = processor.process(set, {"ghost"}, false);
  CHECK_FALSE(out.ok());
  CHECK(out.scans.empty());
  CHECK(out.error == "processing sequence 7: no images of camera 'ghost' in the set");
  sl::pipeline::ImageSet unknown = set;
  unknown.pattern_name = "nope";
  out = processor.process(unknown, {id}, false);
  CHECK(out.error == "processing sequence 7: no decoder for pattern 'nope'");
  sl::pipeline::ImageSet empty = set;
  empty.cameras[0].frames.clear();
  out = processor.process(empty, {id}, true);
  CHECK_FALSE(out.ok());
  CHECK(out.error.rfind("motion compensation: ", 0) == 0);
}

TEST_CASE("stage latency: medians per stage, the total's median and maximum over the last scans") {
  using sl::daemon::StageLatency;
  using sl::daemon::StageTimes;
  StageLatency window;
  CHECK(window.summary().scans == 0);
  CHECK(window.summary().total_max_ms == 0);
  // Stages from a sequence's last exposure at t = 0 (ns).
  const StageTimes one = sl::daemon::stageTimes(0, 3'000'000, 10'000'000, 25'000'000);
  CHECK(one.wait_ms == Approx(3.0));
  CHECK(one.processing_ms == Approx(7.0));
  CHECK(one.publish_ms == Approx(15.0));
  CHECK(one.totalMs() == Approx(25.0));
  // A clock set back between two readings gives 0, not a negative stage.
  CHECK(sl::daemon::stageTimes(5'000'000, 1'000'000, 2'000'000, 3'000'000).wait_ms == 0.0);

  window.add({1, 2, 3});   // total 6
  window.add({3, 4, 5});   // total 12
  window.add({2, 10, 4});  // total 16
  auto s = window.summary();
  CHECK(s.scans == 3);
  CHECK(s.median.wait_ms == Approx(2));
  CHECK(s.median.processing_ms == Approx(4));
  CHECK(s.median.publish_ms == Approx(4));
  CHECK(s.total_median_ms == Approx(12));
  CHECK(s.total_max_ms == Approx(16));
  window.add({1, 1, 1});  // total 3; an even count: the mean of the middle two
  s = window.summary();
  CHECK(s.total_median_ms == Approx((6.0 + 12.0) / 2));
  CHECK(s.median.wait_ms == Approx((1.0 + 2.0) / 2));

  // Only the last kWindow scans count: a slow first scan leaves the window.
  StageLatency slow_start;
  slow_start.add({100, 100, 100});
  for (std::size_t i = 0; i < StageLatency::kWindow; ++i) slow_start.add({1, 2, 3});
  s = slow_start.summary();
  CHECK(s.scans == StageLatency::kWindow);
  CHECK(s.total_max_ms == Approx(6));

  // The latest exposure of a set: its last frame of any camera.
  sl::pipeline::ImageSet set;
  set.trigger_stamp_ns = 1000;
  set.cameras.resize(2);
  set.cameras[0].stamps_ns = {1000, 2000, 3000};
  set.cameras[1].stamps_ns = {1001, 2001, 3005};
  CHECK(sl::daemon::lastExposureNs(set) == 3005);
}

TEST_CASE("reloaded settings reach the processing stage once, the latest of them; bad ones are refused") {
  sl::daemon::PendingSettings pending;
  CHECK_FALSE(pending.take());
  sl::daemon::DaemonConfig first = simConfig(), second = simConfig();
  first.motion.enabled = false;
  second.motion.enabled = true;
  pending.post(first);
  pending.post(second);
  const std::optional<sl::daemon::DaemonConfig> taken = pending.take();
  REQUIRE(taken);
  CHECK(taken->motion.enabled);
  CHECK_FALSE(pending.take());

  sl::daemon::SetProcessor processor(sl::daemon::processingConfigOf(simConfig(), {"top"}));
  const bool configured = processor.motionEnabled();
  sl::daemon::DaemonConfig toggled = simConfig();
  toggled.motion.enabled = !configured;
  CHECK(processor.applyRuntimeSettings(toggled).empty());
  CHECK(processor.motionEnabled() == !configured);
  sl::daemon::DaemonConfig broken = simConfig();
  broken.motion.options.max_shift_px = -1;
  broken.motion.enabled = configured;
  CHECK_FALSE(processor.applyRuntimeSettings(broken).empty());
  CHECK(processor.motionEnabled() == !configured);  // the running settings stay
}

TEST_CASE("device health: silent devices named with their last error; a delivery ends the error") {
  constexpr std::int64_t kS = 1'000'000'000;
  sl::daemon::DeviceHealth health({"top", "side"});
  // Nothing delivered since the scan began at 10 s.
  CHECK(health.silentDevices(10 * kS, 11 * kS, 2.0).empty());
  CHECK(health.silentDevices(10 * kS, 12 * kS + kS / 2, 2.0) ==
        "camera 'top': no frame for 2.5 s; camera 'side': no frame for 2.5 s; "
        "trigger source: no trigger for 2.5 s");
  CHECK_FALSE(health.cameraDelivered(0, 12 * kS));  // no error to clear
  health.cameraFailed(1, "device unplugged");
  CHECK_FALSE(health.triggerDelivered(12 * kS));
  CHECK(health.silentDevices(10 * kS, 13 * kS, 2.0) == "camera 'side': no frame for 3.0 s (device unplugged)");
  CHECK(health.cameraDelivered(1, 13 * kS));  // ends the error: the caller clears it
  CHECK_FALSE(health.cameraDelivered(1, 13 * kS));
  health.triggerFailed("serial port closed");
  CHECK(health.silentDevices(10 * kS, 15 * kS, 2.0) ==
        "camera 'top': no frame for 3.0 s; camera 'side': no frame for 2.0 s; "
        "trigger source: no trigger for 3.0 s (serial port closed)");
  CHECK(health.triggerDelivered(15 * kS));
}

TEST_CASE("memory prefault: the plan follows the cameras, patterns and queue depth; off by default but for the points writer's history") {
  sl::daemon::DaemonConfig config = sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  const std::size_t pixels = std::size_t(config.calibration.camera.width) * config.calibration.camera.height;
  REQUIRE(pixels == 1440 * 1080);
  CHECK_FALSE(config.runtime.prefault_memory);
  {
    // Off: only the points writer's history (reliable, keep-last 4): the
    // 4 clouds a stopped reader leaves unacknowledged and the one written.
    const auto plan = sl::daemon::prefaultPlanOf(config, 64);
    CHECK(config.dds.points_qos.reliable);
    CHECK(config.dds.points_qos.depth == 4);
    CHECK(plan.output_blocks == 4 + 1);
    CHECK(plan.output_block_bytes == pixels * 16 + 4096);
    CHECK(plan.frames * plan.frame_bytes + plan.process_clouds * plan.cloud_bytes == 0);
    CHECK(plan.totalBytes(1) == 5 * (pixels * 16 + 4096));
    // A lighter cloud: decimation 2 of 1440 x 1080 is 720 x 540 points.
    config.dds.points_layout.decimation = 2;
    CHECK(sl::daemon::prefaultPlanOf(config, 64).output_block_bytes == 720 * 540 * 16 + 4096);
    config.dds.points_layout.decimation = 1;
    // Best effort: the writer keeps nothing for its readers.
    config.dds.points_qos.reliable = false;
    CHECK(sl::daemon::prefaultPlanOf(config, 64).totalBytes(1) == 0);
    CHECK(sl::daemon::prefaultPlanOf(config, 64, true).totalBytes(1) == 0);
    config.dds.points_qos.reliable = true;
    // Clouds sent from their own memory: the history holds the processing
    // thread's clouds (4), besides the one processed and the one written.
    const auto kept = sl::daemon::prefaultPlanOf(config, 64, true);
    CHECK(kept.output_blocks * kept.output_block_bytes == 0);
    CHECK(kept.process_clouds == 4 + 2);
    CHECK(kept.cloud_bytes == pixels * 16);
    CHECK(kept.totalBytes(1) == 6 * pixels * 16);
  }

  config.runtime.prefault_memory = true;
  config.runtime.queue_depth = 3;
  auto plan = sl::daemon::prefaultPlanOf(config, 64);
  CHECK(plan.frame_bytes == pixels);         // 8-bit simulated camera
  CHECK(plan.frames == 12 * (3 + 2) + 64);  // the longest pattern, 3+3_both: 12 images
  CHECK(plan.cloud_bytes == pixels * 16);
  CHECK(plan.process_clouds == 3 + 3);
  CHECK(plan.output_blocks == 3 + 3);  // more than the points history (4 + 1)
  CHECK(plan.output_block_bytes == pixels * 16 + 4096);
  config.dds.points_qos.depth = 8;
  CHECK(sl::daemon::prefaultPlanOf(config, 64).output_blocks == 8 + 1);
  config.sim.bit_depth = 12;
  CHECK(sl::daemon::prefaultPlanOf(config, 64).frame_bytes == 2 * pixels);
}

#ifndef SL_SANITIZER_BUILD  // the sanitizers' allocators ignore mallopt
namespace {
long minorFaults() {
  rusage usage{};
  getrusage(RUSAGE_THREAD, &usage);
  return usage.ru_minflt;
}
}  // namespace

TEST_CASE("memory prefault: a thread's first clouds after it touch no fresh pages", "[memory]") {
  REQUIRE(sl::dds::retainLargeSampleMemory());
  constexpr std::size_t kCloud = std::size_t(1440) * 1080 * 16;  // 6,075 pages
  auto touchClouds = [](std::vector<unsigned char*>& clouds) {
    const long before = minorFaults();
    for (std::size_t i = 0; i < clouds.size(); ++i) std::memset(clouds[i], int(i), kCloud);
    return minorFaults() - before;
  };
  // What first touches cost: four clouds of freshly mapped memory. (A new
  // thread's heap is no reference: glibc hands it the arena of a finished
  // thread, with whatever memory that one kept.)
  std::vector<unsigned char*> mapped;
  for (int i = 0; i < 4; ++i)
    mapped.push_back(static_cast<unsigned char*>(
        mmap(nullptr, kCloud, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0)));
  for (unsigned char* c : mapped) REQUIRE(c != MAP_FAILED);
  const long fresh = touchClouds(mapped);
  for (unsigned char* c : mapped) munmap(c, kCloud);
  // A stage thread: prefaulted, then four clouds alive at once.
  long prefaulted = -1;
  std::thread([&] {
    sl::daemon::prefaultThreadHeap(kCloud, 4);
    std::vector<unsigned char*> clouds;
    for (int i = 0; i < 4; ++i) clouds.push_back(static_cast<unsigned char*>(std::malloc(kCloud)));
    prefaulted = touchClouds(clouds);
    for (unsigned char* c : clouds) std::free(c);
  }).join();
  INFO("minor page faults for 4 clouds: fresh memory " << fresh << ", prefaulted heap " << prefaulted);
  CHECK(fresh > 4 * 5000);
  CHECK(prefaulted < 300);
}
#endif

// A finite request's schedule ends after its sequences and the projector
// stops: its trigger source and cameras are silent by design then, while a
// scan may still be on its way; a continuous one's are not.
TEST_CASE("device health: silence after a finite request's schedule is no fault") {
  using Clock = std::chrono::steady_clock;
  sl::daemon::DeviceHealth devices({"top"});
  sl::daemon::EngineStatistics statistics;
  sl::daemon::RequestControl::Health h;
  h.scanning = true;
  h.trigger = TriggerMode::kHardware;
  h.since = Clock::now() - std::chrono::seconds(5);  // nothing delivered since
  h.sequence_s = 0.2;
  h.scans_requested = 1;  // its schedule ended after 0.2 s
  std::string cause = sl::daemon::degradedCause(h, devices, statistics, 1, 2.0);
  INFO("finite: " << cause);
  CHECK(cause.find("no trigger") == std::string::npos);
  CHECK(cause.find("no frame") == std::string::npos);
  CHECK(cause.find("no scan published for") != std::string::npos);  // that is still true

  h.scans_requested = 20;  // 4 s of schedule: silent for 4 s of it
  cause = sl::daemon::degradedCause(h, devices, statistics, 1, 2.0);
  INFO("finite, longer: " << cause);
  CHECK(cause.find("trigger source: no trigger for 4.0 s") != std::string::npos);

  h.scans_requested = 0;  // continuous: silent for all 5 s
  cause = sl::daemon::degradedCause(h, devices, statistics, 1, 2.0);
  INFO("continuous: " << cause);
  CHECK(cause.find("camera 'top': no frame for 5.0 s") != std::string::npos);
  CHECK(cause.find("trigger source: no trigger for 5.0 s") != std::string::npos);
}
