// ScanEngine without DDS: the health signal that feeds the systemd watchdog
// follows the pipeline threads, so a stuck device stops the pings.
#include "support/config_text.h"
#include "support/time_scale.h"
#include <catch2/catch.hpp>

#include <atomic>
#include <cmath>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <filesystem>
#include <functional>
#include <unistd.h>
#include <map>
#include <optional>
#include <set>
#include <thread>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "sl/daemon/config.h"
#include "sl/daemon/devices.h"
#include "sl/files/pattern_config.h"
#include "sl/daemon/scan_engine.h"
#include "sl/drivers/forwarding.h"
#include "sl/drivers/recording.h"
#include "sl/drivers/sim.h"

using namespace std::chrono_literals;

namespace {

// The fault-injecting test cameras below override what they break.
using sl::drivers::ForwardingCamera;

// Under ThreadSanitizer the simulated cameras (and so the engine's decoding
// and triangulation) work at half the width and height, a quarter of the
// pixels: a 1440 x 1080 frame takes ~130 ms to render there, and with the
// decode of the previous set beside it on 2 cores the simulator fell behind
// even at scaledCameraFps. The field of view and the lens stay (focal
// length and principal point in pixels halved, pixel pitch doubled, so the
// same focal length in mm and the same blur in mm), and so do the scene,
// the projector and its patterns: fringes are ~25 camera pixels wide instead
// of ~50. ASan/UBSan and release builds keep the shipped size.
constexpr int kRigDownscale = sl::test::kThreadSanitizer ? 2 : 1;

sl::pipeline::PinholeModel downscaled(sl::pipeline::PinholeModel m, int factor) {
  m.width /= factor;
  m.height /= factor;
  m.fx /= factor;
  m.fy /= factor;
  m.cx = (m.cx + 0.5) / factor - 0.5;  // pixel centres at integers
  m.cy = (m.cy + 0.5) / factor - 0.5;
  return m;  // distortion acts on normalised coordinates: unchanged
}

bool sameCamera(const sl::pipeline::PinholeModel& a, const sl::pipeline::PinholeModel& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy && a.cx == b.cx &&
         a.cy == b.cy && a.distortion == b.distortion;
}

// A simulated sensor's config with its cameras downscaled by `factor`; the
// calibrations that are the simulated rig's own (`calibration: sim`) follow.
sl::daemon::DaemonConfig withDownscaledRig(sl::daemon::DaemonConfig config, int factor) {
  if (factor == 1 || config.sensor != sl::daemon::SensorKind::kSim) return config;
  if (sameCamera(config.calibration.camera, config.sim.rig.camera))
    config.calibration.camera = downscaled(config.calibration.camera, factor);
  config.sim.rig.camera = downscaled(config.sim.rig.camera, factor);
  if (config.sim.second_camera) {
    auto& rig = config.sim.second_camera->rig;
    const auto extra = config.extra_calibrations.find(config.sim.second_camera->camera_id);
    if (extra != config.extra_calibrations.end() && sameCamera(extra->second.camera, rig.camera))
      extra->second.camera = downscaled(extra->second.camera, factor);
    rig.camera = downscaled(rig.camera, factor);
  }
  config.sim.camera_lens.pixel_pitch_um *= factor;
  return config;
}

// `config` with the simulated camera at sl::test::scaledCameraFps (the
// shipped rate outside sanitizer builds), the grouping's image interval to
// match and its wait for late frames (max_age) stretched by the same factor,
// and so the health check's stall timeout: with frames 10x slower a device
// is silent, and a scan takes, 10x longer. (Unscaled, "no scan published"
// came 2 s + one 2 s sequence after a start, before DecodeWatch had seen the
// 3 implausible scans it needs, and took the place of the decode's cause.)
// Cases that test the stall timeout set their own.
sl::daemon::DaemonConfig atTestRate(sl::daemon::DaemonConfig config) {
  config.sim.camera_fps = sl::test::scaledCameraFps(config.sim.camera_fps);
  config.synchroniser.image_interval_ns =
      static_cast<sl::pipeline::TimestampNs>(std::llround(1e9 / config.sim.camera_fps));
  config.synchroniser.max_age_ns *= sl::test::kTimeScale;
  config.runtime.stall_timeout_s *= sl::test::kTimeScale;
  return withDownscaledRig(std::move(config), kRigDownscale);
}

// config/<name> at the test rate.
sl::daemon::DaemonConfig simConfig(const std::string& name = "sim.yaml") {
  return atTestRate(sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/" + name));
}

// A camera whose grab() hangs (ignores its timeout) once `hang` is set, until
// stop(): a driver stuck in a system call.
class HangingCamera : public ForwardingCamera {
 public:
  using ForwardingCamera::ForwardingCamera;
  void stop() override {
    {
      std::lock_guard lock(mutex_);
      stopped_ = true;
    }
    cv_.notify_all();
    inner_->stop();
  }
  std::optional<sl::pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    if (hang) {
      std::unique_lock lock(mutex_);
      cv_.wait(lock, [&] { return stopped_; });
      return std::nullopt;
    }
    return inner_->grab(timeout);
  }
  std::atomic<bool> hang{false};

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stopped_ = false;
};

}  // namespace

TEST_CASE("the engine reports unhealthy while a device thread is stuck, and still shuts down") {
  const auto config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  auto camera = std::make_shared<HangingCamera>(sim->camera());
  sl::daemon::EngineDevices devices{{camera}, sim->projector(), sim->triggerSource()};
  std::atomic<int> clouds{0}, with_maps{0};
  {
    sl::daemon::ScanEngine engine(config, devices, [&](const sl::daemon::ScanResult& r) {
      with_maps += r.maps != nullptr;  // maps only when ResultContents asks for them
      ++clouds;
    });
    std::this_thread::sleep_for(300ms);
    CHECK(engine.healthy());
    REQUIRE(engine.start("", 1).accepted());
    for (int i = 0; i < 100 * sl::test::kTimeScale && clouds == 0; ++i) std::this_thread::sleep_for(50ms);
    CHECK(clouds == 1);
    CHECK(with_maps == 0);
    CHECK(engine.healthy());

    camera->hang = true;  // the next grab() never returns on its own
    const auto start = std::chrono::steady_clock::now();
    while (engine.healthy() && std::chrono::steady_clock::now() - start < sl::test::scaledBound(5s))
      std::this_thread::sleep_for(50ms);
    CHECK_FALSE(engine.healthy());
    // Unhealthy after the 2 s heartbeat limit (plus the grab timeout), not before.
    CHECK(std::chrono::steady_clock::now() - start > 1900ms);
  }  // destruction stops the camera, which releases the stuck grab()
  SUCCEED("engine destroyed");
}

namespace {

using sl::client::CommandResult;
using sl::client::ScanState;
using sl::client::StartRequest;
using sl::client::TriggerMode;

// A projector without single-pattern projection (as the LightCrafter driver).
class SequenceOnlyProjector : public sl::drivers::Projector {
 public:
  explicit SequenceOnlyProjector(std::shared_ptr<sl::drivers::Projector> inner)
      : inner_(std::move(inner)) {}
  std::string id() const override { return "sequence_only"; }
  std::vector<sl::drivers::ProjectorSequence> sequences() const override {
    return inner_->sequences();
  }
  void select(const std::string& name) override { inner_->select(name); }
  void start(int count) override { inner_->start(count); }
  void stop() override { inner_->stop(); }

 private:
  std::shared_ptr<sl::drivers::Projector> inner_;
};

}  // namespace

TEST_CASE("start options are validated with a code and a reason naming the option") {
  const auto config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  std::atomic<int> clouds{0};
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [&](const sl::daemon::ScanResult&) { ++clouds; });
  auto rejected = [&](StartRequest request, CommandResult::Code code, const std::string& words) {
    const CommandResult r = engine.start(request);
    INFO("reason: " << r.reason);
    CHECK(r.code == code);
    CHECK(r.reason.find(words) != std::string::npos);
  };
  StartRequest r;
  r.cameras = {"nope"};
  rejected(r, CommandResult::Code::kInvalidOption, "unknown camera 'nope'");
  r.cameras = {"sim_top", "sim_top"};
  rejected(r, CommandResult::Code::kInvalidOption, "given twice");
  r = {};
  r.delay_s = -1;
  rejected(r, CommandResult::Code::kInvalidOption, "delay");
  r.delay_s = 1;
  r.start_at_ns = sl::pipeline::TimestampNs(4e18);
  rejected(r, CommandResult::Code::kInvalidOption, "not both");
  r.delay_s = 0;
  r.start_at_ns = 1'000'000'000;  // 1970
  rejected(r, CommandResult::Code::kInvalidOption, "in the past");
  r = {};
  r.count = -1;
  rejected(r, CommandResult::Code::kInvalidCount, "count");
  CHECK(engine.status().state == ScanState::kIdle);

  // A delayed start waits (and says until when), can be cancelled, and
  // otherwise begins at its time with its options.
  r = {};
  r.delay_s = 30;
  REQUIRE(engine.start(r).accepted());
  auto s = engine.status();
  CHECK(s.state == ScanState::kWaiting);
  CHECK(s.start_at_ns > sl::pipeline::TimestampNs(29e9) + std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
  CHECK(engine.start(StartRequest{}).code == CommandResult::Code::kBusy);
  CHECK(engine.stop().accepted());
  CHECK(engine.status().state == ScanState::kIdle);

  r.delay_s = 0.3;
  r.count = 1;
  r.cameras = {"sim_top"};
  r.motion_compensation = true;
  const auto requested = std::chrono::steady_clock::now();
  REQUIRE(engine.start(r).accepted());
  s = engine.status();
  CHECK(s.state == ScanState::kWaiting);
  CHECK(s.motion_compensation);
  CHECK(s.cameras == std::vector<std::string>{"sim_top"});
  while (engine.status().state == ScanState::kWaiting &&
         std::chrono::steady_clock::now() - requested < sl::test::scaledBound(3s))
    std::this_thread::sleep_for(5ms);
  const auto began = std::chrono::steady_clock::now() - requested;
  CHECK(began >= 300ms);
  CHECK(began < sl::test::scaledBound(450ms));
  for (int i = 0; i < 100 * sl::test::kTimeScale && clouds == 0; ++i) std::this_thread::sleep_for(50ms);
  CHECK(clouds == 1);
}

TEST_CASE("software trigger is refused when the projector cannot show single patterns") {
  const auto config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  auto projector = std::make_shared<SequenceOnlyProjector>(sim->projector());
  sl::daemon::ScanEngine engine(config, {sim->cameras(), projector, sim->triggerSource()},
                                [](const sl::daemon::ScanResult&) {});
  StartRequest r;
  r.trigger = TriggerMode::kSoftware;
  const CommandResult result = engine.start(r);
  CHECK(result.code == CommandResult::Code::kUnsupported);
  CHECK(result.reason.find("projector 'sequence_only' cannot show single patterns") !=
        std::string::npos);
  // As the configured default, it stops the daemon at start-up instead.
  auto software = config;
  software.runtime.trigger = TriggerMode::kSoftware;
  CHECK_THROWS_WITH(sl::daemon::ScanEngine(software, {sim->cameras(), projector, sim->triggerSource()},
                                           [](const sl::daemon::ScanResult&) {}),
                    Catch::Contains("runtime.trigger is software, but projector"));
}

TEST_CASE("an intensity camera the sensor lacks stops the daemon at start-up") {
  auto config = simConfig();
  config.pattern_intensity_camera["3+3_horizontal"] = "nope";
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  CHECK_THROWS_WITH(sl::daemon::ScanEngine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                           [](const sl::daemon::ScanResult&) {}),
                    Catch::Contains("takes its intensity from camera 'nope'"));
  // A config mistake: ConfigError, so sl_sensord exits 2 (systemd does not restart it).
  CHECK_THROWS_AS(sl::daemon::ScanEngine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                         [](const sl::daemon::ScanResult&) {}),
                  sl::files::ConfigError);
}

// Software trigger, continuous: a pattern switch takes effect at the next
// sequence boundary. The sequence running when the switch is requested is
// completed with the old pattern; every set after it has the new one; no set
// mixes them (a horizontal scan decodes no rows, a 'both' scan does).
TEST_CASE("software trigger: a switch waits for the sequence in progress, never mixing patterns") {
  auto config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  struct Seen {
    std::string pattern;
    double up_valid, vp_valid;
    sl::pipeline::TimestampNs stamp_ns;
  };
  std::mutex mutex;
  std::vector<Seen> seen;
  auto count = [&](const std::string& pattern) {
    std::lock_guard lock(mutex);
    return std::count_if(seen.begin(), seen.end(), [&](const Seen& s) { return s.pattern == pattern; });
  };
  sl::daemon::ScanEngine engine(
      config, {sim->cameras(), sim->projector(), sim->triggerSource()},
      [&](const sl::daemon::ScanResult& r) {
        const double n = double(r.maps->up.total());
        Seen s{r.pattern, cv::countNonZero(r.maps->up == r.maps->up) / n,
               cv::countNonZero(r.maps->vp == r.maps->vp) / n, r.cloud->stamp_ns};
        std::lock_guard lock(mutex);
        seen.push_back(s);
      },
      sl::daemon::ResultContents{sl::daemon::CloudUnit::kMillimetres, true});  // with the maps this test reads
  StartRequest r;
  r.pattern = "3+3_horizontal";
  r.count = 0;
  r.trigger = TriggerMode::kSoftware;
  REQUIRE(engine.start(r).accepted());
  auto waitFor = [&](const std::string& pattern, long n) {
    const auto deadline = std::chrono::steady_clock::now() + sl::test::scaledBound(10s);
    while (count(pattern) < n && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(5ms);
    return count(pattern) >= n;
  };
  REQUIRE(waitFor("3+3_horizontal", 2));
  std::this_thread::sleep_for(100ms);  // into the next sequence
  const auto requested = std::chrono::duration_cast<std::chrono::nanoseconds>(
                             std::chrono::system_clock::now().time_since_epoch())
                             .count();
  REQUIRE(engine.selectPattern("3+3_both").accepted());
  REQUIRE(waitFor("3+3_both", 1));
  REQUIRE(engine.stop().accepted());
  const auto status = engine.status();
  CHECK(status.trigger == TriggerMode::kSoftware);
  CHECK(status.sets_incomplete == 0);
  CHECK(status.sets_dropped == 0);

  std::lock_guard lock(mutex);
  CHECK(status.frames_received >= 6 * seen.size());  // phase_shift_3+3: 6 frames a scan
  std::vector<std::string> runs;
  for (const auto& s : seen) {
    if (runs.empty() || runs.back() != s.pattern) runs.push_back(s.pattern);
    INFO(s.pattern << ": up valid " << s.up_valid << ", vp valid " << s.vp_valid);
    CHECK(s.up_valid > 0.8);
    if (s.pattern == "3+3_horizontal") CHECK(s.vp_valid == 0.0);
    else CHECK(s.vp_valid > 0.8);
  }
  CHECK(runs == std::vector<std::string>{"3+3_horizontal", "3+3_both"});
  // The horizontal sequence in progress at the request was completed: it
  // began after the request minus one horizontal sequence period (the gap
  // between the first two horizontal sets).
  std::vector<sl::pipeline::TimestampNs> horizontal;
  for (const auto& s : seen)
    if (s.pattern == "3+3_horizontal") horizontal.push_back(s.stamp_ns);
  REQUIRE(horizontal.size() >= 3);
  const auto period = horizontal[1] - horizontal[0];
  INFO("request " << (requested - horizontal.back()) * 1e-6 << " ms after the last horizontal "
                  "sequence began; period " << period * 1e-6 << " ms");
  CHECK(requested - horizontal.back() < period);
  CHECK(requested > horizontal.back());
}

namespace {

// A camera that loses the frames `drop(frame_id)` selects and delivers the
// ones `delay(frame_id)` selects one frame late (after the next frame: out
// of order and an image interval late), recording every frame it saw with
// whether it passed. A source that falls behind or drops frames, as a
// camera on a loaded link does.
class LossyCamera : public sl::drivers::Camera {
 public:
  LossyCamera(std::shared_ptr<sl::drivers::Camera> inner, std::function<bool(std::uint64_t)> drop,
              std::function<bool(std::uint64_t)> delay)
      : inner_(std::move(inner)), drop_(std::move(drop)), delay_(std::move(delay)) {}
  std::string id() const override { return inner_->id(); }
  int width() const override { return inner_->width(); }
  int height() const override { return inner_->height(); }
  void start() override { inner_->start(); }
  void stop() override { inner_->stop(); }
  std::optional<sl::pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    if (pending_) return std::exchange(pending_, std::nullopt);
    for (;;) {
      std::optional<sl::pipeline::Frame> frame = inner_->grab(timeout);
      if (!frame) return std::nullopt;
      const bool dropped = drop_(frame->frame_id);
      {
        std::lock_guard lock(mutex_);
        passed_[frame->stamp_ns] = !dropped;
      }
      if (dropped) continue;
      if (held_) {  // the delayed frame goes out after this one
        pending_ = std::exchange(held_, std::nullopt);
        return frame;
      }
      if (delay_(frame->frame_id)) {
        held_ = std::move(frame);
        continue;
      }
      return frame;
    }
  }
  // Stamps of every frame the inner camera delivered -> passed on or not.
  std::map<sl::pipeline::TimestampNs, bool> passed() const {
    std::lock_guard lock(mutex_);
    return passed_;
  }

 private:
  std::shared_ptr<sl::drivers::Camera> inner_;
  std::function<bool(std::uint64_t)> drop_, delay_;
  std::optional<sl::pipeline::Frame> held_, pending_;  // grab() thread only
  mutable std::mutex mutex_;
  std::map<sl::pipeline::TimestampNs, bool> passed_;  // guarded by mutex_
};

// Records the trigger stamps it passes on.
class RecordingTrigger : public sl::drivers::TriggerSource {
 public:
  explicit RecordingTrigger(std::shared_ptr<sl::drivers::TriggerSource> inner)
      : inner_(std::move(inner)) {}
  std::optional<sl::drivers::TriggerEvent> next(std::chrono::milliseconds timeout) override {
    auto t = inner_->next(timeout);
    if (t) {
      std::lock_guard lock(mutex_);
      stamps_.push_back(t->stamp_ns);
    }
    return t;
  }
  void stop() override { inner_->stop(); }
  std::vector<sl::pipeline::TimestampNs> stamps() const {
    std::lock_guard lock(mutex_);
    return stamps_;
  }

 private:
  std::shared_ptr<sl::drivers::TriggerSource> inner_;
  mutable std::mutex mutex_;
  std::vector<sl::pipeline::TimestampNs> stamps_;  // guarded by mutex_
};

}  // namespace

TEST_CASE("a source that drops and delays frames costs exactly the sequences it spoiled") {
  auto config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  // Frame 7 of every 15 lost: sequences 1 and 3 of every 5 (6 frames each)
  // lose one frame, so 3 in 5 complete. Every 4th frame comes late.
  auto camera = std::make_shared<LossyCamera>(
      sim->camera(), [](std::uint64_t id) { return id % 15 == 7; },
      [](std::uint64_t id) { return id % 4 == 1; });
  auto trigger = std::make_shared<RecordingTrigger>(sim->triggerSource());
  sl::daemon::EngineDevices devices{{camera}, sim->projector(), trigger};
  std::mutex mutex;
  std::set<sl::pipeline::TimestampNs> delivered;  // cloud stamps = trigger stamps
  sl::daemon::ScanEngine engine(config, devices, [&](const sl::daemon::ScanResult& r) {
    std::lock_guard lock(mutex);
    delivered.insert(r.cloud->stamp_ns);
  });
  REQUIRE(engine.start("3+3_horizontal", 0).accepted());
  constexpr std::size_t kSequences = 20;
  for (int i = 0; i < 200 * sl::test::kTimeScale && trigger->stamps().size() < kSequences + 3; ++i)
    std::this_thread::sleep_for(50ms);
  std::this_thread::sleep_for(sl::test::scaledBound(500ms));  // the last sequences processed
  const sl::pipeline::TimestampNs snapshot_ns = sl::pipeline::systemClockNs();
  const sl::daemon::EngineStatus status = engine.status();
  REQUIRE(engine.stop().accepted());

  const auto triggers = trigger->stamps();
  REQUIRE(triggers.size() >= kSequences);
  const auto passed = camera->passed();
  const sl::pipeline::TimestampNs dt = config.synchroniser.image_interval_ns;
  // A sequence can complete when all 6 frames passed (frames the simulator
  // itself dropped under load count as lost too).
  auto passedAt = [&](sl::pipeline::TimestampNs t) {
    const auto it = passed.lower_bound(t - dt / 10);
    return it != passed.end() && it->first <= t + dt / 10 && it->second;
  };
  // Spoiled sequences older than max_age plus their own length (a frame is
  // purged max_age after its stamp) and some slack are purged and counted by
  // the time of the status snapshot (800 ms in all at 30 Hz).
  const sl::pipeline::TimestampNs counted_before =
      snapshot_ns - config.synchroniser.max_age_ns - 6 * dt - 600'000'000;
  // Whether the simulator delivered the frame at all (passed on or dropped).
  auto renderedAt = [&](sl::pipeline::TimestampNs t) {
    const auto it = passed.lower_bound(t - dt / 10);
    return it != passed.end() && it->first <= t + dt / 10;
  };
  std::size_t expected = 0, spoiled_old = 0, spoiled_old_frames = 0, got = 0, rendered = 0;
  for (std::size_t k = 0; k < kSequences; ++k) {
    int passed_frames = 0, rendered_frames = 0;
    for (int i = 0; i < 6; ++i) {
      passed_frames += passedAt(triggers[k] + i * dt);
      rendered_frames += renderedAt(triggers[k] + i * dt);
    }
    const bool complete = passed_frames == 6;
    rendered += rendered_frames == 6;
    std::lock_guard lock(mutex);
    const bool published = delivered.count(triggers[k]) > 0;
    INFO("sequence " << k << " complete " << complete);
    CHECK_FALSE((published && !complete));  // never a set with a frame missing
    expected += complete;
    got += published;
    if (!complete && triggers[k] < counted_before) {
      ++spoiled_old;
      spoiled_old_frames += passed_frames;  // 5, or fewer where the simulator dropped
    }
  }
  // Every complete sequence is published unless a queue overflowed (counted).
  CHECK(got + status.sets_overflow >= expected);
  CHECK(got <= expected);
  CHECK(status.frames_overflow == 0);
  // 3 of 5 sequences survive the drop rule. The simulator drops whole
  // sequences when it falls behind, and frame ids count those too, so the
  // rule spoils at most 2 in 5 consecutive sequences (+1 at the ends) of
  // those it rendered whole. Under TSan on a loaded machine the simulator
  // loses more of them; the case asks for enough to mean something.
  INFO("rendered whole " << rendered << ", complete " << expected);
  CHECK(expected <= kSequences * 3 / 5 + 1);
  CHECK(rendered >= (sl::test::kTimeScale == 1 ? kSequences / 2 : kSequences / 4));
  CHECK(expected + kSequences * 2 / 5 + 1 >= rendered);
  // The spoiled ones are counted as incomplete, their frames as unmatched.
  CHECK(status.sets_incomplete >= spoiled_old);
  CHECK(status.frames_unmatched >= spoiled_old_frames);
}

// CloudUnit::kMetres (the daemon's, for DDS): the clouds are triangulated
// from the calibration in metres, so they are the millimetre clouds / 1000
// to float rounding, with the same invalid pixels.
TEST_CASE("clouds in metres are the clouds in millimetres scaled, with the same invalid pixels") {
  auto config = simConfig();
  auto scanOnce = [&](sl::daemon::CloudUnit unit) {
    const auto sim = sl::drivers::SimulatedSensor::create(config.sim);  // same seed: same images
    std::mutex mutex;
    std::condition_variable cv;
    std::optional<sl::daemon::ScanResult> first;
    sl::daemon::ScanEngine engine(
        config, {sim->cameras(), sim->projector(), sim->triggerSource()},
        [&](const sl::daemon::ScanResult& r) {
          std::lock_guard lock(mutex);
          if (!first) first = r;
          cv.notify_all();
        },
        sl::daemon::ResultContents{unit});
    REQUIRE(engine.start("3+3_horizontal", 1).accepted());
    std::unique_lock lock(mutex);
    REQUIRE(cv.wait_for(lock, sl::test::scaledBound(20s), [&] { return first.has_value(); }));
    return *first;
  };
  const sl::daemon::ScanResult mm = scanOnce(sl::daemon::CloudUnit::kMillimetres);
  const sl::daemon::ScanResult m = scanOnce(sl::daemon::CloudUnit::kMetres);
  CHECK(mm.cloud_unit_m == 1e-3);
  CHECK(m.cloud_unit_m == 1.0);
  REQUIRE(mm.cloud->points.size() == m.cloud->points.size());
  std::size_t valid = 0, mismatched = 0;
  for (std::size_t i = 0; i < mm.cloud->points.size(); ++i) {
    const auto& a = mm.cloud->points[i];
    const auto& b = m.cloud->points[i];
    if (std::isnan(a.z) || std::isnan(b.z)) {
      mismatched += std::isnan(a.z) != std::isnan(b.z);
      continue;
    }
    ++valid;
    const float tolerance = 2e-6f * std::abs(a.z);  // a few float ulps of the depth
    mismatched += !(std::abs(b.x * 1000.0f - a.x) <= tolerance && std::abs(b.y * 1000.0f - a.y) <= tolerance &&
                    std::abs(b.z * 1000.0f - a.z) <= tolerance && a.intensity == b.intensity);
  }
  CHECK(valid > mm.cloud->points.size() / 2);
  CHECK(mismatched == 0);
}

namespace {

// A camera that can be made to deliver nothing (a device gone quiet) or to
// fail every grab (a device gone), and then to recover.
class FaultyCamera : public ForwardingCamera {
 public:
  using ForwardingCamera::ForwardingCamera;
  std::optional<sl::pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    if (fail) {
      std::this_thread::sleep_for(10ms);
      throw std::runtime_error("device unplugged");
    }
    if (silent) {
      std::this_thread::sleep_for(timeout);
      return std::nullopt;
    }
    return inner_->grab(timeout);
  }
  std::atomic<bool> silent{false}, fail{false};
};

// A trigger source that can be made to deliver no triggers.
class FaultyTrigger : public sl::drivers::TriggerSource {
 public:
  explicit FaultyTrigger(std::shared_ptr<sl::drivers::TriggerSource> inner) : inner_(std::move(inner)) {}
  std::optional<sl::drivers::TriggerEvent> next(std::chrono::milliseconds timeout) override {
    if (silent) {
      std::this_thread::sleep_for(timeout);
      return std::nullopt;
    }
    return inner_->next(timeout);
  }
  void stop() override { inner_->stop(); }
  std::atomic<bool> silent{false};

 private:
  std::shared_ptr<sl::drivers::TriggerSource> inner_;
};

}  // namespace

TEST_CASE("a camera or trigger that stalls makes the scan degraded with its cause; it recovers") {
  auto config = simConfig();
  config.runtime.stall_timeout_s = 0.6 * sl::test::kTimeScale;
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  auto camera = std::make_shared<FaultyCamera>(sim->camera());
  auto trigger = std::make_shared<FaultyTrigger>(sim->triggerSource());
  std::atomic<int> clouds{0};
  sl::daemon::ScanEngine engine(config, {{camera}, sim->projector(), trigger},
                                [&](const sl::daemon::ScanResult&) { ++clouds; });
  using sl::daemon::EngineStatus;
  auto waitFor = [&](const std::function<bool(const EngineStatus&)>& condition, std::chrono::milliseconds bound) {
    const auto until = std::chrono::steady_clock::now() + sl::test::scaledBound(bound);
    EngineStatus s = engine.status();
    while (!condition(s) && std::chrono::steady_clock::now() < until) {
      std::this_thread::sleep_for(20ms);
      s = engine.status();
    }
    return s;
  };
  // 6-pattern sequences: 5 scans/s at the shipped 30 Hz (a fifth of that
  // counts as scanning well; the rate is smoothed).
  const double scan_rate_hz = config.sim.camera_fps / 6;
  auto scanningWell = [&](int after) {
    return [&, after](const EngineStatus& s) {
      return s.state == ScanState::kScanning && clouds > after && s.scan_rate_hz > scan_rate_hz / 5;
    };
  };
  REQUIRE(engine.start("", 0).accepted());
  EngineStatus s = waitFor(scanningWell(2), 5000ms);
  REQUIRE(s.state == ScanState::kScanning);
  CHECK(s.degraded_reason.empty());
  const double frame_rate_hz = config.sim.camera_fps / 3;  // 10 Hz of the shipped 30 Hz camera
  s = waitFor([&](const EngineStatus& s) { return s.frame_rate_hz > frame_rate_hz; }, 3000ms);
  CHECK(s.frame_rate_hz > frame_rate_hz);
  const std::uint64_t errors_before = s.errors_reported;

  SECTION("a silent camera") {
    const auto t0 = sl::pipeline::systemClockNs();
    camera->silent = true;
    s = waitFor([](const EngineStatus& s) { return s.state == ScanState::kDegraded; }, 3000ms);
    REQUIRE(s.state == ScanState::kDegraded);
    INFO("degraded: " << s.degraded_reason);
    CHECK(s.degraded_reason.find("camera 'sim_top': no frame for") != std::string::npos);
    CHECK(s.last_error.find("degraded: camera 'sim_top'") != std::string::npos);
    CHECK(s.last_error_ns >= t0);
    CHECK(s.errors_reported > errors_before);
    // The rates fall to 0 instead of keeping their last values.
    s = waitFor([](const EngineStatus& s) { return s.scan_rate_hz == 0 && s.frame_rate_hz == 0; }, 3000ms);
    CHECK(s.scan_rate_hz == 0);
    CHECK(s.frame_rate_hz == 0);
    // A scan that keeps failing says so as well.
    s = waitFor([](const EngineStatus& s) { return s.degraded_reason.find("no scan published") != std::string::npos; },
                3000ms);
    CHECK(s.degraded_reason.find("no scan published for") != std::string::npos);

    const int before = clouds;
    camera->silent = false;
    s = waitFor(scanningWell(before + 1), 5000ms);
    CHECK(s.state == ScanState::kScanning);
    CHECK(s.degraded_reason.empty());
    CHECK(s.last_error.empty());  // the fault it reported has recovered
    CHECK(s.last_error_ns == 0);
    CHECK(s.errors_reported > errors_before);  // still counted
  }
  SECTION("a camera that fails every grab") {
    camera->fail = true;
    s = waitFor([](const EngineStatus& s) { return s.state == ScanState::kDegraded; }, 3000ms);
    REQUIRE(s.state == ScanState::kDegraded);
    INFO("degraded: " << s.degraded_reason);
    CHECK(s.degraded_reason.find("camera 'sim_top': no frame for") != std::string::npos);
    CHECK(s.degraded_reason.find("(device unplugged)") != std::string::npos);
    const int before = clouds;
    camera->fail = false;
    s = waitFor(scanningWell(before + 1), 5000ms);
    CHECK(s.state == ScanState::kScanning);
    CHECK(s.last_error.empty());
  }
  SECTION("a silent trigger source") {
    trigger->silent = true;
    s = waitFor([](const EngineStatus& s) { return s.state == ScanState::kDegraded; }, 3000ms);
    REQUIRE(s.state == ScanState::kDegraded);
    INFO("degraded: " << s.degraded_reason);
    CHECK(s.degraded_reason.find("trigger source: no trigger for") != std::string::npos);
    s = waitFor([](const EngineStatus& s) { return s.scan_rate_hz == 0; }, 3000ms);
    CHECK(s.scan_rate_hz == 0);
    const int before = clouds;
    trigger->silent = false;
    s = waitFor(scanningWell(before + 1), 5000ms);
    CHECK(s.state == ScanState::kScanning);
    CHECK(s.last_error.empty());
  }
  // STOP ends a degraded scan like any other; idle is never degraded.
  CHECK(engine.stop().accepted());
  s = engine.status();
  CHECK(s.state == ScanState::kIdle);
  CHECK(s.degraded_reason.empty());
  CHECK(s.scan_rate_hz == 0);
}

TEST_CASE("last_error ages out after runtime.last_error_hold_s and keeps its count") {
  auto config = simConfig();
  config.runtime.last_error_hold_s = 0.3;
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [](const sl::daemon::ScanResult&) {});
  const auto t0 = sl::pipeline::systemClockNs();
  engine.reportError("config reload failed: test", "reload");
  auto s = engine.status();
  CHECK(s.last_error == "config reload failed: test");
  CHECK(s.last_error_ns >= t0);
  CHECK(s.errors_reported == 1);
  engine.clearError("camera:");  // another source: kept
  CHECK(engine.status().last_error == "config reload failed: test");
  engine.clearError("reload");   // a good reload clears it
  CHECK(engine.status().last_error.empty());
  engine.reportError("something else");
  CHECK(engine.status().last_error == "something else");
  std::this_thread::sleep_for(400ms);
  s = engine.status();
  CHECK(s.last_error.empty());
  CHECK(s.last_error_ns == 0);
  CHECK(s.errors_reported == 2);
}

TEST_CASE("a recording stops at its quota with the reason, counting the sets it did not record") {
  auto config = simConfig();
  const std::string root = std::filesystem::temp_directory_path() /
                           ("sl_quota_" + std::to_string(::getpid()));
  std::filesystem::remove_all(root);
  config.runtime.recording_root = root;
  SECTION("a set count") {
    config.runtime.recording_max_sets = 2;
    const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
    std::atomic<int> clouds{0};
    sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                  [&](const sl::daemon::ScanResult&) { ++clouds; });
    REQUIRE(engine.start("", 0, "quota").accepted());
    const auto until = std::chrono::steady_clock::now() + sl::test::scaledBound(20s);
    while (clouds < 5 && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(50ms);
    REQUIRE(engine.stop().accepted());
    // The recorder's queue drains (PNG encoding may lag far behind under load).
    auto accounted = [&](const sl::daemon::EngineStatus& s) {
      return s.sets_recorded + s.sets_over_quota + s.sets_not_recorded;
    };
    const auto drained = std::chrono::steady_clock::now() + sl::test::scaledBound(30s);
    while (accounted(engine.status()) < static_cast<std::uint64_t>(clouds.load()) &&
           std::chrono::steady_clock::now() < drained)
      std::this_thread::sleep_for(50ms);
    const auto s = engine.status();
    CHECK(clouds >= 5);  // scanning goes on; only the recording stops
    CHECK(s.sets_recorded == 2);
    CHECK(s.sets_over_quota >= 1);
    // Every set is recorded, over the quota, or dropped by a full queue: none uncounted.
    CHECK(accounted(s) >= static_cast<std::uint64_t>(clouds.load()));
    CHECK(s.recording.empty());
    INFO("last_error: " << s.last_error);
    CHECK(s.last_error.find("recording 'quota' stopped after 2 sets") != std::string::npos);
    CHECK(s.last_error.find("runtime.recording_max_sets (2 sets) reached") != std::string::npos);
    CHECK(sl::drivers::listRecordedSets(root + "/quota").size() == 2);
  }
  SECTION("a size in bytes") {
    config.runtime.recording_max_mb = 1;  // a 1440 x 1080 set of 6 frames is 9.3 MB raw
    const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
    sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                  [](const sl::daemon::ScanResult&) {});
    const auto& cal = config.sim.rig.camera;
    REQUIRE(static_cast<double>(cal.width) * cal.height * 6 > 1e6);
    REQUIRE(engine.start("", 2, "big").accepted());
    const auto until = std::chrono::steady_clock::now() + sl::test::scaledBound(10s);
    while (engine.status().sets_over_quota < 2 && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(50ms);
    const auto s = engine.status();
    CHECK(s.sets_recorded == 0);
    CHECK(s.sets_over_quota == 2);
    CHECK(s.last_error.find("runtime.recording_max_mb (1.0 MB) reached") != std::string::npos);
  }
  SECTION("the free-space floor refuses the start") {
    config.runtime.recording_min_free_mb = 1ull << 40;  // an exabyte: more than any disk
    const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
    sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                  [](const sl::daemon::ScanResult&) {});
    const CommandResult r = engine.start("", 1, "full");
    INFO("reason: " << r.reason);
    CHECK(r.code == CommandResult::Code::kDeviceError);
    CHECK(r.reason.find("below runtime.recording_min_free_mb") != std::string::npos);
    CHECK(engine.status().state == ScanState::kIdle);
  }
  std::filesystem::remove_all(root);
}

// Each recorded set keeps the description of its pattern (pattern.yml), so
// that sl_process can refuse a pattern file of the same name with another
// sequence (issue 32).
TEST_CASE("a recorded set keeps its pattern's description", "[engine][record]") {
  auto config = simConfig();
  const std::string root = std::filesystem::temp_directory_path() /
                           ("sl_described_" + std::to_string(::getpid()));
  std::filesystem::remove_all(root);
  config.runtime.recording_root = root;
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [](const sl::daemon::ScanResult&) {});
  REQUIRE(engine.start("", 1, "described").accepted());
  const auto until = std::chrono::steady_clock::now() + sl::test::scaledBound(30s);
  while (engine.status().sets_recorded < 1 && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(50ms);
  REQUIRE(engine.status().sets_recorded == 1);
  const auto sets = sl::drivers::listRecordedSets(root + "/described");
  REQUIRE(sets.size() == 1);
  const sl::pipeline::ImageSet set = sl::drivers::readRecordedSet(sets[0], false);
  const sl::pipeline::PatternSpec* pattern = config.findPattern(set.pattern_name);
  REQUIRE(pattern != nullptr);
  const std::string described = sets[0] + "/pattern.yml";
  REQUIRE(std::filesystem::exists(described));
  const sl::pipeline::PatternSpec recorded = sl::files::loadPattern(described);
  CHECK(recorded.name == pattern->name);
  CHECK(recorded.frequencies == pattern->frequencies);
  CHECK(sl::files::patternDifferences(recorded, *pattern).empty());
  std::filesystem::remove_all(root);
}

// A replayed recording whose sets describe their pattern otherwise than the
// config's pattern of that name (sim.yaml's 3+3_horizontal recorded at 40
// periods, replayed with a config that says 16) is refused when the devices
// open, naming the set's pattern.yml and the difference.
TEST_CASE("a replay refuses a config pattern other than the recorded description",
          "[engine][record]") {
  auto config = simConfig();
  const std::string root = std::filesystem::temp_directory_path() /
                           ("sl_replay_described_" + std::to_string(::getpid()));
  std::filesystem::remove_all(root);
  const sl::pipeline::PatternSpec* recorded = config.findPattern("3+3_horizontal");
  REQUIRE(recorded != nullptr);
  REQUIRE(recorded->frequencies == std::vector<double>{40, 1});
  sl::pipeline::ImageSet set;
  set.sequence_id = 1;
  set.pattern_name = recorded->name;
  sl::pipeline::CameraImages camera;
  camera.camera_id = "sim_top";
  camera.bit_depth = 8;
  for (int f = 0; f < recorded->frameCount(); ++f) {
    camera.frames.push_back(cv::Mat(config.calibration.camera.height,
                                    config.calibration.camera.width, CV_8UC1, cv::Scalar(100)));
    camera.stamps_ns.push_back(1'000'000'000 + f * 100'000'000);
  }
  set.cameras = {camera};
  sl::drivers::createRecording(root, "test");
  sl::drivers::writeRecordedSet(root, 1, set, sl::files::patternYaml(*recorded));
  config.sensor = sl::daemon::SensorKind::kReplay;
  config.replay.dir = root;
  std::shared_ptr<void> keep_alive;
  // As recorded: opens.
  CHECK_NOTHROW(sl::daemon::openDevices(config, keep_alive));
  keep_alive.reset();
  // The same name at 16 periods: refused, naming the file and the difference.
  for (auto& pattern : config.patterns)
    if (pattern.name == "3+3_horizontal") pattern.frequencies = {16, 1};
  try {
    sl::daemon::openDevices(config, keep_alive);
    FAIL("opened a replay whose recorded pattern differs from the config's");
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    INFO(message);
    CHECK(message.find(root + "/set_000001/pattern.yml") != std::string::npos);
    CHECK(message.find("'3+3_horizontal'") != std::string::npos);
    CHECK(message.find("frequencies: [40, 1] vs [16, 1]") != std::string::npos);
  }
  std::filesystem::remove_all(root);
}

// The daemon's decoder.projector_gamma reaches the engine's decoding: the
// simulated projector at gamma 2.2 (a projector in video mode) decoded
// without compensation loses or misplaces many pixels of the 3+3 pattern;
// with decoder.projector_gamma: 2.2 the cloud is as complete as a linear
// projector's.
TEST_CASE("decoder.projector_gamma takes effect in the engine's decoding", "[engine][gamma]") {
  const auto replaced = [](std::string text, const std::string& from, const std::string& to) {
    const auto at = text.find(from);
    REQUIRE(at != std::string::npos);
    return text.replace(at, from.size(), to);
  };
  const std::string shipped = sl::test::shippedSimConfigText();
  // With `publish_implausible`, a cloud whose decode health is implausible
  // is published too (counted); without, the request ends with the cause.
  std::string last_error;
  const auto scan = [&](const std::string& text, bool publish_implausible = false) {
    auto config = atTestRate(sl::daemon::parseConfig(text, std::string(SL_SOURCE_DIR) + "/config/sim.yaml"));
    config.runtime.publish_implausible = publish_implausible;
    const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
    std::mutex mutex;
    std::shared_ptr<const sl::pipeline::PointCloud> cloud;
    sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                  [&](const sl::daemon::ScanResult& r) {
                                    std::lock_guard<std::mutex> lock(mutex);
                                    if (!cloud) cloud = r.cloud;
                                  });
    REQUIRE(engine.start("", 1).accepted());
    for (int i = 0; i < 200 * sl::test::kTimeScale; ++i) {
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (cloud) break;
      }
      std::this_thread::sleep_for(50ms);
    }
    if (!publish_implausible) {
      // Without a cloud the request ends at once (an implausible decode).
      for (int i = 0; i < 100 * sl::test::kTimeScale && engine.status().state != ScanState::kIdle; ++i)
        std::this_thread::sleep_for(20ms);
    }
    std::lock_guard<std::mutex> lock(mutex);
    last_error = engine.status().last_error;
    return cloud ? cloud->validCount() : std::size_t{0};
  };
  const std::string gamma_sim = replaced(shipped, "projector_gamma: 1.0", "projector_gamma: 2.2");
  const std::size_t linear = scan(shipped);
  CHECK(linear > 0);
  // A gamma-2.2 projector decoded as linear: the 3-step phase errors are
  // amplified 40 times by the 40:1 unwrapping, the fringe orders are random
  // (docs/decode-health.md): implausible, no cloud, the cause named ...
  CHECK(scan(gamma_sim) == 0);
  INFO("last error: " << last_error);
  CHECK(last_error.find("implausible") != std::string::npos);
  CHECK(last_error.find("projector_gamma") != std::string::npos);
  // ... and published on request, with fewer valid points.
  const std::size_t uncompensated = scan(gamma_sim, true);
  const std::size_t compensated =
      scan(replaced(gamma_sim, "max_unwrap_error: 0.3", "max_unwrap_error: 0.3\n  projector_gamma: 2.2"));
  WARN("valid points: linear projector " << linear << ", gamma 2.2 uncompensated " << uncompensated
                                         << ", compensated " << compensated);
  CHECK(compensated > 0.97 * linear);
  CHECK(uncompensated < 0.9 * compensated);
}

// Software trigger on a two-camera sensor: only the cameras a request
// triangulates with are triggered (a simulated camera not triggered renders
// nothing, which halves sl_eval wall's rendering).
TEST_CASE("software trigger: only the request's cameras are triggered") {
  auto config = simConfig("sim-motion.yaml");
  config.sim.motion = {};
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  std::mutex mutex;
  std::vector<std::string> cameras;
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [&](const sl::daemon::ScanResult& r) {
                                  std::lock_guard lock(mutex);
                                  cameras.push_back(r.camera_id);
                                });
  StartRequest r;
  r.pattern = "3+3_horizontal";
  r.count = 1;
  r.trigger = TriggerMode::kSoftware;
  r.cameras = {"sim_left"};
  const auto before = sim->counters().frames_delivered;
  REQUIRE(engine.start(r).accepted());
  const auto deadline = std::chrono::steady_clock::now() + sl::test::scaledBound(20s);
  auto got = [&] {
    std::lock_guard lock(mutex);
    return cameras.size();
  };
  while (got() < 1 && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(5ms);
  REQUIRE(got() == 1);
  for (int i = 0; i < 400 * sl::test::kTimeScale && engine.status().state != ScanState::kIdle; ++i)
    std::this_thread::sleep_for(5ms);
  CHECK(cameras[0] == "sim_left");
  // 6 frames of the one camera, none of sim_top.
  CHECK(sim->counters().frames_delivered - before == 6);
  CHECK(engine.status().sets_incomplete == 0);
}

TEST_CASE("the status says where each scan's latency went: waiting, processing, publishing") {
  auto config = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  std::atomic<int> published{0};
  // Publishing that takes 40 ms: the publish stage must show it, the others not.
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [&](const sl::daemon::ScanResult&) {
                                  std::this_thread::sleep_for(40ms);
                                  ++published;
                                });
  CHECK(engine.status().latency_ms == 0);  // no scan yet
  // Continuous: a simulator that falls behind (sanitizer builds) costs
  // sequences, and a finite request's schedule would then end short.
  REQUIRE(engine.start("3+3_horizontal", 0).accepted());
  const auto until = std::chrono::steady_clock::now() + sl::test::scaledBound(30s);
  while (published < 4 && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(20ms);
  REQUIRE(published >= 4);
  CHECK(engine.stop().accepted());
  // The stages are stored after the callback returns.
  std::this_thread::sleep_for(sl::test::scaledBound(100ms));
  const sl::daemon::EngineStatus s = engine.status();
  CHECK(s.publish_ms >= 40.0);
  CHECK(s.processing_ms > 0.0);
  CHECK(s.wait_ms > 0.0);  // the last frame is delivered after its exposure starts
  CHECK(s.latency_ms >= 40.0);
  CHECK(s.latency_max_ms >= s.latency_ms);
  // The medians of the stages of the same scans add up to about the total's.
  CHECK(s.wait_ms + s.processing_ms + s.publish_ms == Approx(s.latency_ms).epsilon(0.5));
}

// A pattern file that does not describe the projected frames: the simulator
// projects sim.yaml's 3+3_horizontal (40 periods and the unit cue), the
// engine decodes with another description under the same name. Its clouds
// are implausible: counted, not published, a continuous scan degraded with
// the cause, a finite request ended with it; the right description
// publishes and stays healthy.
TEST_CASE("an implausible decode degrades the scan with its cause; its clouds are not published",
          "[engine][health]") {
  const auto truth = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(truth.sim);
  struct Case {
    const char* what;
    std::vector<double> frequencies;  // of the description; the frames have {40, 1}
    bool plausible;
  };
  const Case c = GENERATE(Case{"right", {40, 1}, true}, Case{"reversed frequency list", {1, 40}, false},
                          Case{"wrong fine frequency", {16, 1}, false});
  INFO(c.what);
  auto config = truth;
  for (auto& p : config.patterns)
    if (p.name == "3+3_horizontal") p.frequencies = c.frequencies;
  std::atomic<int> clouds{0};
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [&](const sl::daemon::ScanResult&) { ++clouds; });
  using sl::daemon::EngineStatus;
  auto waitFor = [&](const std::function<bool(const EngineStatus&)>& condition, std::chrono::milliseconds bound) {
    const auto until = std::chrono::steady_clock::now() + sl::test::scaledBound(bound);
    EngineStatus s = engine.status();
    while (!condition(s) && std::chrono::steady_clock::now() < until) {
      std::this_thread::sleep_for(20ms);
      s = engine.status();
    }
    return s;
  };
  SECTION("continuous") {
    REQUIRE(engine.start("3+3_horizontal", 0).accepted());
    EngineStatus s;
    if (c.plausible) {
      s = waitFor([&](const EngineStatus&) { return clouds >= 4; }, 5000ms);
      CHECK(clouds >= 4);
      CHECK(s.state == ScanState::kScanning);
      CHECK(s.degraded_reason.empty());
      CHECK(s.clouds_implausible == 0);
      CHECK(s.decode_modulated_fraction > 0.5);
      CHECK(s.decode_consistent_fraction > 0.95);
      CHECK(s.decode_residual_median < 0.08);  // the limit is 0.17
    } else {
      s = waitFor([](const EngineStatus& s) { return s.state == ScanState::kDegraded; }, 5000ms);
      INFO("degraded: " << s.degraded_reason);
      REQUIRE(s.state == ScanState::kDegraded);
      CHECK(s.degraded_reason.find("decode of pattern '3+3_horizontal' by camera 'sim_top' implausible") !=
            std::string::npos);
      CHECK(s.degraded_reason.find("fail unwrapping") != std::string::npos);
      CHECK(s.last_error.find("degraded: decode of pattern") != std::string::npos);
      CHECK(s.clouds_implausible >= 3);  // DecodeWatch::kScansToDegrade
      CHECK(s.decode_consistent_fraction < 0.85);
      CHECK(s.decode_residual_median > 0.1);
      CHECK(clouds == 0);  // none published
      CHECK(s.scans_done == 0);
    }
    WARN(c.what << ": modulated " << s.decode_modulated_fraction << ", consistent "
                << s.decode_consistent_fraction << ", residual median " << s.decode_residual_median
                << ", implausible clouds " << s.clouds_implausible << ", published " << clouds);
    CHECK(engine.stop().accepted());
    CHECK(engine.status().degraded_reason.empty());
  }
  SECTION("finite") {
    REQUIRE(engine.start("3+3_horizontal", 2).accepted());
    const EngineStatus s = waitFor([](const EngineStatus& s) { return s.state == ScanState::kIdle; }, 5000ms);
    REQUIRE(s.state == ScanState::kIdle);
    INFO("last error: " << s.last_error);
    if (c.plausible) {
      CHECK(clouds == 2);
      CHECK(s.last_error.empty());
    } else {
      CHECK(clouds == 0);
      CHECK(s.clouds_implausible >= 1);
      CHECK(s.last_error.find("decode of pattern '3+3_horizontal' by camera 'sim_top' implausible") !=
            std::string::npos);
      CHECK(s.last_error.find("cloud not published") != std::string::npos);
    }
  }
}

TEST_CASE("runtime.publish_implausible publishes implausible clouds, counted, the scan still degraded",
          "[engine][health]") {
  const auto truth = simConfig();
  const auto sim = sl::drivers::SimulatedSensor::create(truth.sim);
  auto config = truth;
  config.runtime.publish_implausible = true;
  for (auto& p : config.patterns)
    if (p.name == "3+3_horizontal") p.frequencies = {16, 1};
  std::atomic<int> clouds{0};
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [&](const sl::daemon::ScanResult&) { ++clouds; });
  REQUIRE(engine.start("3+3_horizontal", 0).accepted());
  const auto until = std::chrono::steady_clock::now() + sl::test::scaledBound(5000ms);
  while (engine.status().state != ScanState::kDegraded && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(20ms);
  const auto s = engine.status();
  INFO("degraded: " << s.degraded_reason);
  CHECK(s.state == ScanState::kDegraded);
  CHECK(s.clouds_implausible >= 3);
  CHECK(clouds >= 3);
  CHECK(engine.stop().accepted());
}

// A storm of SET_PATTERN requests (100/s, as many clients would send) during
// a continuous hardware-triggered scan: every switch waits for a complete
// sequence of the running schedule, a request replaces the pending pattern
// but not its time, so the storm delays switches and never stops scanning.
// The status says so in last_error, never `degraded` with a device as cause.
TEST_CASE("a storm of pattern switches delays them and never stops scanning", "[engine][storm]") {
  auto config = simConfig();  // its stall timeout scaled
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  std::mutex mutex;
  std::map<std::string, int> clouds_of;  // pattern -> clouds, guarded by mutex
  std::atomic<int> clouds{0};
  sl::daemon::ScanEngine engine(config, {sim->cameras(), sim->projector(), sim->triggerSource()},
                                [&](const sl::daemon::ScanResult& r) {
                                  std::lock_guard lock(mutex);
                                  ++clouds_of[r.pattern];
                                  ++clouds;
                                });
  const std::vector<std::string> patterns = engine.patterns();
  REQUIRE(patterns.size() >= 2);
  REQUIRE(engine.start("", 0).accepted());
  const auto first_until = std::chrono::steady_clock::now() + sl::test::scaledBound(5s);
  while (clouds == 0 && std::chrono::steady_clock::now() < first_until) std::this_thread::sleep_for(10ms);
  REQUIRE(clouds > 0);

  const int before = clouds;
  int requests = 0, degraded = 0;
  bool said_delayed = false;
  std::string degraded_cause, last_requested;
  const auto storm_until = std::chrono::steady_clock::now() + sl::test::scaledBound(6s);
  while (std::chrono::steady_clock::now() < storm_until) {
    // The worst case: every request names a pattern other than the running one.
    last_requested = engine.status().pattern == patterns[0] ? patterns[1] : patterns[0];
    const CommandResult reply = engine.selectPattern(last_requested);
    INFO("request " << requests << ": " << reply.reason);
    REQUIRE(reply.accepted());
    ++requests;
    const sl::daemon::EngineStatus s = engine.status();
    if (s.state == ScanState::kDegraded) {
      ++degraded;
      degraded_cause = s.degraded_reason;
    }
    said_delayed = said_delayed || s.last_error.find("pattern switches delayed") != std::string::npos;
    std::this_thread::sleep_for(10ms);
  }
  const int during = clouds - before;
  std::map<std::string, int> seen;
  {
    std::lock_guard lock(mutex);
    seen = clouds_of;
  }
  INFO(requests << " requests, " << during << " clouds during the storm, degraded " << degraded
                << " times (" << degraded_cause << ")");
  CHECK(during >= 10);
  CHECK(degraded == 0);
  CHECK(said_delayed);
  CHECK(seen.size() == patterns.size());  // the switches were delayed, not dropped
  // The latest request wins once the storm is over.
  const auto settle_until = std::chrono::steady_clock::now() + sl::test::scaledBound(3s);
  while (engine.status().pattern != last_requested && std::chrono::steady_clock::now() < settle_until)
    std::this_thread::sleep_for(10ms);
  CHECK(engine.status().pattern == last_requested);
  CHECK(engine.stop().accepted());
}
