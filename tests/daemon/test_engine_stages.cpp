// The scan engine's stages without its threads: start-request validation (a
// pure function) and set processing (errors as values).
#include <catch2/catch.hpp>

#include <opencv2/core.hpp>

#include "engine/set_processor.h"
#include "engine/start_validation.h"
#include "sl/daemon/config.h"
#include "sl/drivers/sim.h"

using sl::daemon::CommandResult;
using sl::daemon::ScanState;
using sl::daemon::StartRequest;
using sl::daemon::TriggerMode;
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
