// VersaVIS against a fake board that behaves like the devel/sl_sensor
// firmware (fake_versavis_board.h): init handshake, camera frames restamped
// with the board's camera trigger times, the board's converging clock,
// reset at start, TX_STOP at close, board log messages, md5 check,
// re-negotiation after lost sync and on unknown topic ids, the watchdog; and
// the daemon's hardware path (composeVersavis + LightCrafter 4500 on the fake
// DLPC350 + ScanEngine) producing complete image sets within 5 s of start-up.
// Every wait is bounded.
#include <catch2/catch.hpp>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>

#include "fake_dlpc350.h"
#include "fake_versavis_board.h"
#include "sl/daemon/config.h"
#include "sl/daemon/devices.h"
#include "sl/daemon/scan_engine.h"
#include "sl/drivers/lightcrafter4500.h"
#include "sl/drivers/versavis.h"
#include "support/time_scale.h"

using namespace sl;
using namespace std::chrono_literals;
using sl::test::FakeVersavisBoard;
using sl::test::FakeVersavisOptions;
namespace rs = sl::drivers::rosserial;

namespace {

using Clock = std::chrono::steady_clock;

// A camera triggered by the fake board: each trigger of its channel becomes
// a frame (own frame counter, host stamp) delivered `latency` later.
class TriggeredCamera : public drivers::Camera {
 public:
  TriggeredCamera(std::string id, std::uint64_t first_frame_id, cv::Mat image)
      : id_(std::move(id)), next_id_(first_frame_id), image_(std::move(image)) {}
  std::string id() const override { return id_; }
  int width() const override { return image_.cols; }
  int height() const override { return image_.rows; }
  void start() override {}
  void stop() override {
    std::lock_guard lock(mutex_);
    stopped_ = true;
    cv_.notify_all();
  }
  void trigger(std::int64_t host_ns) {
    std::lock_guard lock(mutex_);
    pipeline::Frame f;
    f.image = image_;
    f.stamp_ns = host_ns + 1'000'000;  // the camera's own stamp: host clock, exposure start
    f.frame_id = next_id_++;
    queue_.push_back({Clock::now() + 15ms, std::move(f)});
    cv_.notify_all();
  }
  std::optional<pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    std::unique_lock lock(mutex_);
    const auto deadline = Clock::now() + timeout;
    for (;;) {
      if (stopped_) return std::nullopt;
      if (!queue_.empty() && queue_.front().first <= Clock::now()) {
        auto f = std::move(queue_.front().second);
        queue_.pop_front();
        return f;
      }
      const auto wake = queue_.empty() ? deadline : std::min(deadline, queue_.front().first);
      if (Clock::now() >= deadline) return std::nullopt;
      cv_.wait_until(lock, wake);
    }
  }

 private:
  std::string id_;
  std::uint64_t next_id_;
  cv::Mat image_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stopped_ = false;
  std::deque<std::pair<Clock::time_point, pipeline::Frame>> queue_;
};

drivers::VersavisConfig sourceConfig(const FakeVersavisBoard& board) {
  drivers::VersavisConfig c;
  c.device = board.devicePath();
  c.reconnect_interval = 100ms;
  c.negotiation_retry = 300ms;
  c.camera_channels = {"/versavis/cam1/"};
  c.reset_at_start = false;
  return c;
}

struct Logged {
  std::mutex mutex;
  std::vector<std::pair<int, std::string>> lines;
  drivers::VersavisTriggerSource::Log sink() {
    return [this](int level, const std::string& m) {
      std::lock_guard lock(mutex);
      lines.emplace_back(level, m);
    };
  }
  bool contains(const std::string& text) {
    std::lock_guard lock(mutex);
    for (const auto& l : lines)
      if (l.second.find(text) != std::string::npos) return true;
    return false;
  }
};

// Pumps next() on a thread (the daemon's trigger thread), keeping events.
struct Pump {
  explicit Pump(drivers::VersavisTriggerSource& s) : source(s) {
    thread = std::thread([this] {
      while (running) {
        try {
          if (auto e = source.next(20ms)) {
            std::lock_guard lock(mutex);
            events.push_back(*e);
          }
        } catch (const std::exception& e) {
          std::lock_guard lock(mutex);
          errors.push_back(e.what());
        }
      }
    });
  }
  ~Pump() { halt(); }
  void halt() {
    running = false;
    if (thread.joinable()) thread.join();
  }
  std::vector<drivers::TriggerEvent> taken() {
    std::lock_guard lock(mutex);
    return events;
  }
  bool hasError(const std::string& text) {
    std::lock_guard lock(mutex);
    for (const auto& e : errors)
      if (e.find(text) != std::string::npos) return true;
    return false;
  }
  drivers::VersavisTriggerSource& source;
  std::atomic<bool> running{true};
  std::mutex mutex;
  std::vector<drivers::TriggerEvent> events;
  std::vector<std::string> errors;
  std::thread thread;
};

// Polls `done` until it holds or `limit` (x10 in sanitizer builds) passes.
template <typename F>
bool waitFor(F&& done, std::chrono::milliseconds limit) {
  const auto deadline = Clock::now() + sl::test::scaledBound(limit);
  while (Clock::now() < deadline) {
    if (done()) return true;
    std::this_thread::sleep_for(10ms);
  }
  return done();
}

}  // namespace

TEST_CASE("firmware-like board: init handshake, then restamped frames on the board's clock") {
  FakeVersavisOptions o;
  o.init_pulse_period = 300ms;
  o.setup_delay = 100ms;
  std::shared_ptr<TriggeredCamera> camera =
      std::make_shared<TriggeredCamera>("cam", 5000, cv::Mat(4, 4, CV_8UC1, cv::Scalar(0)));
  FakeVersavisBoard board(o, [&](int channel, std::uint64_t, std::int64_t host) {
    if (channel == 1) camera->trigger(host);
  });
  Logged log;
  auto source = std::make_shared<drivers::VersavisTriggerSource>(sourceConfig(board), log.sink());
  drivers::VersavisRestampCamera restamped(camera, source, 0);
  Pump pump(*source);

  // Until the handshake the board pulses the camera and publishes no
  // projector time; frames pass with their own stamps.
  int learning = 0;
  std::vector<pipeline::Frame> frames;
  const auto t0 = Clock::now();
  while (Clock::now() - t0 < sl::test::scaledBound(5s) && frames.size() < 60) {
    auto f = restamped.grab(100ms);
    if (!f) continue;
    if (!source->cameraInitialised(0)) {
      ++learning;
      CHECK(pump.taken().empty());
      CHECK_FALSE(board.allInitialised());
    } else {
      frames.push_back(*f);
    }
  }
  CHECK(learning >= 1);
  REQUIRE(frames.size() == 60);
  CHECK(board.allInitialised());
  const auto c = source->counters();
  CHECK(c.inits_sent == 1);
  CHECK(c.frames_restamped >= 60);
  CHECK(log.contains("matched board channel '/versavis/cam1/'"));
  // Restamped: the board's time of the same trigger, i.e. the camera's host
  // stamp (trigger + 1 ms) moved by the board's clock offset (+100 ms, less
  // as the filter converges); consecutive frames 33.3 ms apart, except
  // where a time reply stepped the board's clock (-10.5 ms per reply at
  // first: the fake's filter steps, as a worst case).
  const std::int64_t offset = board.offsetNs();
  CHECK(offset > 40'000'000);  // still far from converged: restamping is what matters
  int steps = 0;
  for (std::size_t i = 4; i < frames.size(); ++i) {  // past the last init pulses: the timers
    const double dt_ms = (frames[i].stamp_ns - frames[i - 1].stamp_ns) * 1e-6;
    if (std::abs(dt_ms - 33.33) > 1.0) {
      ++steps;
      CHECK(dt_ms == Approx(33.33 - 10.5).margin(3.0));
    }
  }
  CHECK(steps <= 2);  // 2 s of frames, a time reply every 2.5 s
  // Projector triggers: every frame whose trigger coincided with a
  // projector trigger has the same board time (t_c - t_p = 0 within eq. 12).
  waitFor([&] { return pump.taken().size() >= 3; }, 2000ms);
  const auto triggers = pump.taken();
  REQUIRE(triggers.size() >= 3);
  int aligned = 0;
  for (const auto& t : triggers)
    for (const auto& f : frames)
      if (std::llabs(f.stamp_ns - t.stamp_ns) < 6'666'666) {
        ++aligned;
        CHECK(std::llabs(f.stamp_ns - t.stamp_ns) < 1'000'000);
      }
  CHECK(aligned >= 2);
}

TEST_CASE("the board's clock converges under the driver's time replies (time scaled x10)") {
  FakeVersavisOptions o;
  o.time_scale = 10;  // 2.5 s sync period -> 0.25 s; a minute -> 6 s
  o.setup_delay = 50ms;
  FakeVersavisBoard board(o);
  const auto t0 = Clock::now();
  const double at0 = board.offsetNs() * 1e-6;  // before any time reply
  drivers::VersavisConfig c = sourceConfig(board);
  c.camera_channels.clear();
  drivers::VersavisTriggerSource source(c);
  Pump pump(source);
  auto offsetMsAt = [&](double s) {
    std::this_thread::sleep_until(
        t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s)));
    return board.offsetNs() * 1e-6;
  };
  const double at30 = offsetMsAt(3.05), at60 = offsetMsAt(6.05);
  CHECK(at0 == Approx(100).margin(1));
  CHECK(at30 == Approx(47).margin(12));  // issue 19's model: +50 ms at 30 s
  CHECK(at60 == Approx(8).margin(8));    // +7 ms at 60 s
  CHECK(board.timeReplies() >= 20);
  CHECK(source.counters().time_requests >= 20);
}

TEST_CASE("lost sync: the board stops after 11 s without time replies, the host renegotiates") {
  FakeVersavisOptions o;
  o.time_scale = 10;  // board gives up after 1.1 s
  o.setup_delay = 50ms;
  o.init_pulse_period = 100ms;
  FakeVersavisBoard board(o);
  drivers::VersavisConfig c = sourceConfig(board);
  c.sync_timeout = 1500ms;  // 15 s scaled
  c.watchdog = 10000ms;
  Logged log;
  drivers::VersavisTriggerSource source(c, log.sink());
  {
    Pump pump(source);
    REQUIRE(waitFor([&] { return board.configured(); }, 2000ms));
  }
  // Nobody reads the port (a stalled host): no time replies for 1.1 s.
  REQUIRE(waitFor([&] { return !board.configured(); }, 2500ms));
  Pump pump(source);
  // The board, unconfigured, sends nothing; 15 s (scaled) later the host asks again.
  REQUIRE(waitFor([&] { return board.configured(); }, 4000ms));
  CHECK(source.counters().renegotiations >= 1);
  CHECK(log.contains("requesting the topics again"));
}

TEST_CASE("unknown topic id, board log, md5, watchdog, reset at start, TX_STOP at close") {
  SECTION("a packet on a topic id that was not negotiated makes the host ask again") {
    FakeVersavisOptions o;
    o.setup_delay = 50ms;
    FakeVersavisBoard board(o);
    drivers::VersavisTriggerSource source(sourceConfig(board));
    Pump pump(source);
    REQUIRE(waitFor([&] { return board.configured(); }, 2000ms));
    const auto requests = source.counters().topic_requests;
    std::this_thread::sleep_for(400ms);  // past negotiation_retry
    board.publishUnknownTopic();
    REQUIRE(waitFor([&] { return source.counters().topic_requests > requests; }, 2000ms));
    CHECK(source.counters().unknown_topics >= 1);
  }
  SECTION("board log messages reach the log with their level") {
    FakeVersavisOptions o;
    o.setup_delay = 50ms;
    FakeVersavisBoard board(o);
    Logged log;
    drivers::VersavisTriggerSource source(sourceConfig(board), log.sink());
    Pump pump(source);
    REQUIRE(waitFor([&] { return board.configured(); }, 2000ms));
    board.log(2, "Camera.cpp: exposure pin is set to 0");
    REQUIRE(waitFor([&] { return log.contains("board: Camera.cpp: exposure pin"); }, 2000ms));
    std::lock_guard lock(log.mutex);
    for (const auto& [level, text] : log.lines)
      if (text.find("exposure pin") != std::string::npos) CHECK(level == 2);
    CHECK(source.counters().log_messages == 1);
  }
  SECTION("a camera time topic with another md5 is refused, naming topic and sums") {
    FakeVersavisOptions o;
    o.setup_delay = 50ms;
    o.md5 = "00000000000000000000000000000000";
    FakeVersavisBoard board(o);
    drivers::VersavisTriggerSource source(sourceConfig(board));
    Pump pump(source);
    REQUIRE(waitFor(
        [&] {
          return pump.hasError(
              "has md5 00000000000000000000000000000000, "
              "expected a1a1eed10c75c0326a67a86fc18b029d");
        },
        2000ms));
    CHECK(source.counters().md5_mismatches >= 1);
  }
  SECTION("a silent board is reported once by the watchdog, then noted when it talks again") {
    FakeVersavisOptions o;
    o.setup_delay = 50ms;
    FakeVersavisBoard board(o);
    drivers::VersavisConfig c = sourceConfig(board);
    c.watchdog = 400ms;
    c.camera_channels.clear();  // the board waits for no init: it pulses nothing
    Logged log;
    drivers::VersavisTriggerSource source(c, log.sink());
    Pump pump(source);
    // Configured, the board asks for the time every 2.5 s: 400 ms of silence in between.
    REQUIRE(waitFor([&] { return pump.hasError("board silent for 400 ms"); }, 3000ms));
    CHECK(source.counters().silent);
    REQUIRE(waitFor([&] { return log.contains("board talking again"); }, 4000ms));
    CHECK_FALSE(source.counters().silent);
  }
  SECTION("reset at start: the board reboots, the host reconnects quietly and renegotiates") {
    FakeVersavisOptions o;
    o.setup_delay = 50ms;
    o.reboot_delay = 100ms;
    o.init_pulse_period = 100ms;
    FakeVersavisBoard board(o);
    drivers::VersavisConfig c = sourceConfig(board);
    c.reset_at_start = true;
    Logged log;
    drivers::VersavisTriggerSource source(c, log.sink());
    Pump pump(source);
    REQUIRE(waitFor([&] { return board.boots() == 2 && board.configured(); }, 3000ms));
    CHECK(board.resets() == 1);
    CHECK(source.counters().resets_sent == 1);
    CHECK(source.counters().disconnects == 1);
    CHECK_FALSE(pump.hasError("disconnected"));  // expected: not an error
    CHECK(log.contains("reset sent on '/versavis/reset'"));
    std::this_thread::sleep_for(300ms);
    CHECK(board.resets() == 1);  // once per process, not after every reconnect
  }
  SECTION("TX_STOP at close, unless configured off") {
    FakeVersavisOptions o;
    o.setup_delay = 50ms;
    FakeVersavisBoard board(o);
    for (bool stop : {true, false}) {
      drivers::VersavisConfig c = sourceConfig(board);
      c.tx_stop_at_close = stop;
      const int before = board.txStops();
      {
        drivers::VersavisTriggerSource source(c);
        Pump pump(source);
        REQUIRE(waitFor([&] { return board.configured(); }, 2000ms));
      }
      waitFor([&] { return board.txStops() > before; }, 500ms);
      CHECK(board.txStops() == before + (stop ? 1 : 0));
    }
  }
}

namespace {

struct HardwareRig {
  explicit HardwareRig(bool with_channels, bool reset) {
    config = daemon::loadConfig(SL_SOURCE_DIR "/config/hardware-paper.yaml");
    const auto& calib = config.calibration.camera;
    image = cv::Mat(calib.height, calib.width, CV_8UC1, cv::Scalar(40));
    top = std::make_shared<TriggeredCamera>("top", 100, image);
    left = std::make_shared<TriggeredCamera>("left", 7000, image);
    FakeVersavisOptions o;  // the firmware's timing: 1 s setup delay, 1 Hz init pulses
    board = std::make_unique<FakeVersavisBoard>(o, [this](int ch, std::uint64_t, std::int64_t h) {
      if (ch == 1) {
        top->trigger(h);
        left->trigger(h);
      }
    });
    // The board is powered before the daemon starts: past its setup delay.
    REQUIRE(waitFor([&] { return board->ready(); }, 3000ms));
    auto& v = config.hardware.versavis;
    v.device = board->devicePath();
    v.reset_at_start = reset;
    if (!with_channels) v.camera_channels.clear();
    auto& p = config.hardware.projector;
    p.reply_timeout = 100ms;
    p.validation_poll = 1ms;
    start = Clock::now();
    projector = std::make_shared<drivers::LightCrafter4500Projector>(
        p, [this] { return std::make_unique<sl::test::FakeDlpc350>(dlpc); });
    trigger = daemon::openVersavis(config);
    devices = daemon::composeVersavis(config, {top, left}, projector, trigger);
  }
  daemon::DaemonConfig config;
  cv::Mat image;
  std::shared_ptr<TriggeredCamera> top, left;
  std::unique_ptr<FakeVersavisBoard> board;
  sl::test::FakeDlpc350State dlpc;
  std::shared_ptr<drivers::LightCrafter4500Projector> projector;
  std::shared_ptr<drivers::VersavisTriggerSource> trigger;
  daemon::EngineDevices devices;
  Clock::time_point start;
};

}  // namespace

// Decorators that record what the engine's synchroniser receives.
class RecordingCamera : public drivers::Camera {
 public:
  explicit RecordingCamera(std::shared_ptr<drivers::Camera> c) : c_(std::move(c)) {}
  std::string id() const override { return c_->id(); }
  int width() const override { return c_->width(); }
  int height() const override { return c_->height(); }
  void start() override { c_->start(); }
  void stop() override { c_->stop(); }
  std::optional<pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    auto f = c_->grab(timeout);
    if (f) {
      std::lock_guard lock(mutex);
      stamps.push_back(f->stamp_ns);
    }
    return f;
  }
  std::mutex mutex;
  std::vector<std::int64_t> stamps;

 private:
  std::shared_ptr<drivers::Camera> c_;
};

class RecordingTrigger : public drivers::TriggerSource {
 public:
  explicit RecordingTrigger(std::shared_ptr<drivers::TriggerSource> t) : t_(std::move(t)) {}
  std::optional<drivers::TriggerEvent> next(std::chrono::milliseconds timeout) override {
    auto e = t_->next(timeout);
    if (e) {
      std::lock_guard lock(mutex);
      stamps.push_back(e->stamp_ns);
    }
    return e;
  }
  void stop() override { t_->stop(); }
  std::mutex mutex;
  std::vector<std::int64_t> stamps;

 private:
  std::shared_ptr<drivers::TriggerSource> t_;
};

TEST_CASE("hardware path on the firmware-like board: complete image sets within 5 s of start-up") {
  HardwareRig rig(/*with_channels=*/true, /*reset=*/true);
  std::vector<std::shared_ptr<RecordingCamera>> cameras;
  for (auto& c : rig.devices.cameras) {
    cameras.push_back(std::make_shared<RecordingCamera>(c));
    c = cameras.back();
  }
  auto triggers = std::make_shared<RecordingTrigger>(rig.devices.trigger);
  rig.devices.trigger = triggers;
  std::mutex mutex;
  std::vector<std::pair<double, std::uint64_t>> sets;  // (s after start-up, scan index)
  daemon::ScanEngine engine(rig.config, rig.devices, [&](const daemon::ScanResult& r) {
    std::lock_guard lock(mutex);
    if (sets.empty() || sets.back().second != r.scan_index)
      sets.emplace_back(std::chrono::duration<double>(Clock::now() - rig.start).count(),
                        r.scan_index);
  });
  REQUIRE(engine.start("3+3_horizontal", 0).accepted());
  const bool got = waitFor(
      [&] {
        std::lock_guard lock(mutex);
        return sets.size() >= 8;
      },
      10000ms);
  const auto status = engine.status();
  INFO("last_error: " << status.last_error);
  REQUIRE(got);
  engine.stop();
  std::lock_guard lock(mutex);
  const double first_s = sets.front().first;
  INFO("first complete image set " << first_s << " s after start-up");
  WARN("hardware path: first complete image set "
       << first_s
       << " s after start-up (board reset, "
          "0.5 s reboot, 1 s firmware setup delay, 1 Hz init pulses, 2 matches)");
  CHECK(first_s < 5.0 * sl::test::kTimeScale);
  CHECK(rig.board->resets() == 1);
  CHECK(rig.board->allInitialised());
  // The trigger/camera offset the synchroniser sees, for every projector
  // trigger and both cameras (eq. 12: |t_c - (t_p + i dt)| <= 0.2 dt for the
  // frame nearest each pattern's slot), while the board's clock is still
  // ~+100 ms off the host's.
  const double dt = static_cast<double>(rig.config.synchroniser.image_interval_ns);
  std::vector<std::int64_t> trigger_stamps;
  {
    std::lock_guard t_lock(triggers->mutex);
    trigger_stamps = triggers->stamps;
  }
  int within = 0, beyond = 0;
  double worst_within = 0;
  for (const std::int64_t tp : trigger_stamps) {
    double worst = 0;
    bool complete = true;
    for (const auto& cam : cameras) {
      std::lock_guard c_lock(cam->mutex);
      if (cam->stamps.empty() || cam->stamps.back() < tp + 6 * dt) complete = false;
      for (int i = 0; i < 6 && complete; ++i) {
        double best = 1e18;
        for (const std::int64_t tc : cam->stamps)
          best = std::min(best, std::abs(static_cast<double>(tc - tp) - i * dt));
        worst = std::max(worst, best);
      }
    }
    if (!complete) continue;  // frames still to come when the engine stopped
    if (worst < 1e6) {
      ++within;
      worst_within = std::max(worst_within, worst);
    } else {
      ++beyond;
      WARN("a projector trigger's frames are " << worst * 1e-6
                                               << " ms off: a step of the board's clock");
    }
  }
  INFO(within << " triggers within 1 ms (worst " << worst_within * 1e-6 << " ms), " << beyond
              << " beyond");
  CHECK(within >= 6);
  CHECK(worst_within < 0.2 * dt);
  CHECK(rig.board->offsetNs() > 20'000'000);  // the host clock would have been ~+100 ms off
  const auto c = rig.trigger->counters();
  CHECK(c.inits_sent == 1);  // both cameras share /versavis/cam1/
  INFO("sets incomplete " << status.sets_incomplete << ", frames unstamped "
                          << c.frames_unstamped);
  // The fake board runs in real time: in a sanitizer build (5-15x slower
  // host threads) frames miss their stamps and sequences straddle clock
  // steps for want of CPU, not for a bug (seen under ThreadSanitizer:
  // 3 beyond, 3 incomplete, 4 unstamped), so these hold in other builds only.
  if (sl::test::kTimeScale == 1) {
    // Beyond: a sequence straddling a step of the board's clock (a time
    // reply: one per 2.5 s while the filter converges), at most one here.
    CHECK(beyond <= 1);
    CHECK(status.sets_incomplete <= 2);
    CHECK(c.frames_unstamped == 0);
  }
}

TEST_CASE("hardware path without the handshake: the board never publishes projector times") {
  HardwareRig rig(/*with_channels=*/false, /*reset=*/false);
  daemon::ScanEngine engine(rig.config, rig.devices, [](const daemon::ScanResult&) {});
  REQUIRE(engine.start("3+3_horizontal", 0).accepted());
  std::this_thread::sleep_for(2500ms);  // 1 s setup, then pulses at 1 Hz
  CHECK(rig.board->configured());
  CHECK(rig.board->projectorTriggers() == 0);
  CHECK_FALSE(rig.board->allInitialised());
  CHECK(engine.status().scans_done == 0);
}
