// Sequence start times from camera frame stamps (no trigger board).
#include <catch2/catch.hpp>
#include <thread>

#include "sl/drivers/camera_stamp_trigger.h"
#include "support/time_scale.h"

using namespace sl::drivers;
using namespace std::chrono_literals;

namespace {
constexpr std::int64_t kPeriod = 33333333;  // 30 Hz
}

TEST_CASE("every Nth frame starts a sequence; dropped frames keep the count") {
  CameraStampSequencer s;
  CHECK_FALSE(s.push(1000));  // no sequence set: nothing
  s.setSequence(6, kPeriod);
  const std::int64_t t0 = 1'000'000'000;
  std::vector<TriggerEvent> events;
  for (int i = 0; i < 18; ++i) {
    if (i == 7 || i == 12) continue;  // frame 12 starts the third sequence: dropped
    const std::int64_t jitter = (i % 2 ? 1 : -1) * 2'000'000;  // +-2 ms
    if (auto e = s.push(t0 + i * kPeriod + jitter)) events.push_back(*e);
  }
  REQUIRE(events.size() == 2);
  CHECK(events[0].stamp_ns == t0 - 2'000'000);
  CHECK(events[1].stamp_ns == t0 + 6 * kPeriod - 2'000'000);
  CHECK(events[1].sequence_index == 1);
}

TEST_CASE("a pause, a clock jump or reset() restarts the numbering; offset applied") {
  CameraStampTriggerConfig cfg;
  cfg.offset_ns = 500;
  CameraStampSequencer s(cfg);
  s.setSequence(3, kPeriod);
  std::int64_t t = 5'000'000'000;
  CHECK(s.push(t));
  CHECK_FALSE(s.push(t += kPeriod));
  // Projector stopped for 1 s: the next frame is a sequence start.
  auto e = s.push(t += 1'000'000'000);
  REQUIRE(e);
  CHECK(e->stamp_ns == t - 500);
  CHECK_FALSE(s.push(t += kPeriod));
  CHECK(s.push(t - 10));  // stamp going backwards
  CHECK_FALSE(s.push(t += kPeriod));
  s.reset();
  CHECK(s.push(t += kPeriod));
  CHECK_THROWS_AS(s.setSequence(0, kPeriod), std::invalid_argument);
  CHECK_THROWS_AS(s.setSequence(3, 0), std::invalid_argument);
}

namespace {
class ScriptedCamera : public Camera {
 public:
  std::string id() const override { return "cam"; }
  int width() const override { return 4; }
  int height() const override { return 4; }
  void start() override {}
  void stop() override {}
  std::optional<Frame> grab(std::chrono::milliseconds) override {
    Frame f;
    f.stamp_ns = next_stamp;
    next_stamp += kPeriod;
    return f;
  }
  bool hasSoftwareTrigger() const override { return true; }
  void triggerSoftware() override { ++software_triggers; }
  std::int64_t next_stamp = 1'000'000'000;
  int software_triggers = 0;
};
class RecordingProjector : public Projector {
 public:
  std::string id() const override { return "p"; }
  std::vector<ProjectorSequence> sequences() const override { return {{"a", 2}}; }
  void select(const std::string& n) override { selected = n; }
  void start(int) override { ++starts; }
  void stop() override {}
  bool canProjectSingle() const override { return true; }
  void projectSingle(int index) override { held = index; }
  std::string selected;
  int starts = 0;
  int held = -1;
};
}  // namespace

TEST_CASE("trigger source fed by a camera tap, sequence length from a projector tap") {
  auto source = std::make_shared<CameraStampTriggerSource>();
  auto inner = std::make_shared<RecordingProjector>();
  SequenceTapProjector projector(inner, source, {{"a", {2, kPeriod}}});
  auto cam = std::make_shared<ScriptedCamera>();
  StampTapCamera camera(cam, source);
  CHECK_THROWS_AS(projector.select("b"), std::invalid_argument);
  projector.select("a");
  projector.start(0);
  CHECK(inner->starts == 1);
  for (int i = 0; i < 4; ++i) REQUIRE(camera.grab(10ms));
  auto e0 = source->next(10ms);
  auto e1 = source->next(10ms);
  REQUIRE(e0);
  REQUIRE(e1);
  CHECK(e1->stamp_ns - e0->stamp_ns == 2 * kPeriod);
  CHECK_FALSE(source->next(10ms));
  std::thread t([&] {
    std::this_thread::sleep_for(30ms);
    source->stop();
  });
  const auto t0 = std::chrono::steady_clock::now();
  CHECK_FALSE(source->next(sl::test::scaledBound(5000ms)));
  t.join();
  CHECK(std::chrono::steady_clock::now() - t0 < sl::test::scaledBound(2000ms));
}

TEST_CASE("the taps pass software triggering through; its frames start no sequence") {
  auto source = std::make_shared<CameraStampTriggerSource>();
  auto inner = std::make_shared<RecordingProjector>();
  SequenceTapProjector projector(inner, source, {{"a", {2, kPeriod}}});
  auto cam = std::make_shared<ScriptedCamera>();
  StampTapCamera camera(cam, source);
  CHECK(camera.hasSoftwareTrigger());
  CHECK(projector.canProjectSingle());
  projector.select("a");
  for (int i = 0; i < 4; ++i) {
    projector.projectSingle(i % 2);
    camera.triggerSoftware();
    REQUIRE(camera.grab(10ms));
  }
  CHECK(inner->held == 1);
  CHECK(cam->software_triggers == 4);
  CHECK_FALSE(source->next(10ms));  // software-triggered frames are no sequence starts
  projector.start(0);               // the running sequence is numbered again
  REQUIRE(camera.grab(10ms));
  CHECK(source->next(10ms));
}
