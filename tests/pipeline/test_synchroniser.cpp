// Synchroniser: grouping camera frames by trigger time (eq. 12).
#include <algorithm>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <catch2/catch.hpp>
#include <opencv2/core.hpp>

#include "sl/pipeline/synchroniser.h"

using namespace sl::pipeline;

namespace {

constexpr TimestampNs kDt = 10'000'000;  // 10 ms between camera triggers
constexpr TimestampNs kTol = 2'000'000;  // 0.2 * dt
constexpr TimestampNs kT0 = 1'700'000'000'000'000'000;

SynchroniserOptions options() {
  SynchroniserOptions o;
  o.image_interval_ns = kDt;
  o.tolerance_lower = 0.2;
  o.tolerance_upper = 0.2;
  o.max_age_ns = 500'000'000;
  return o;
}

// A 2x2 frame whose pixels hold `tag`, to check which frame went where.
Frame frame(TimestampNs stamp, int tag, int bit_depth = 8) {
  Frame f;
  f.image = cv::Mat(2, 2, CV_8UC1, cv::Scalar(tag));
  f.stamp_ns = stamp;
  f.frame_id = static_cast<std::uint64_t>(tag);
  f.bit_depth = bit_depth;
  return f;
}

int tagOf(const cv::Mat& image) { return image.at<std::uint8_t>(0, 0); }

// Pushes the n frames of a sequence triggered at t for one camera, frame i
// offset by jitter[i] (ns) and tagged base + i.
void pushSequence(Synchroniser& s, std::size_t camera, TimestampNs t, int n, int base,
                  const std::vector<TimestampNs>& jitter = {}) {
  for (int i = 0; i < n; ++i) {
    const TimestampNs j = i < static_cast<int>(jitter.size()) ? jitter[i] : 0;
    s.pushFrame(camera, frame(t + i * kDt + j, base + i));
  }
}

}  // namespace

TEST_CASE("frames group into an image set in pattern order", "[synchroniser]") {
  Synchroniser s({"left"}, options());
  s.setPattern("3+3", 6);
  s.pushTrigger(kT0);
  pushSequence(s, 0, kT0, 6, 10, {300, -500, 0, 1'000'000, -1'000'000, 7});
  auto sets = s.takeCompleted();
  REQUIRE(sets.size() == 1);
  const ImageSet& set = *sets[0];
  CHECK(set.sequence_id == 0);
  CHECK(set.pattern_name == "3+3");
  CHECK(set.trigger_stamp_ns == kT0);
  REQUIRE(set.cameras.size() == 1);
  const CameraImages& cam = set.cameras[0];
  CHECK(cam.camera_id == "left");
  CHECK(cam.bit_depth == 8);
  REQUIRE(cam.frames.size() == 6);
  REQUIRE(cam.stamps_ns.size() == 6);
  for (int i = 0; i < 6; ++i) CHECK(tagOf(cam.frames[i]) == 10 + i);
  CHECK(cam.stamps_ns[3] == kT0 + 3 * kDt + 1'000'000);
  CHECK(s.takeCompleted().empty());

  // The next sequence gets the next id.
  const TimestampNs t1 = kT0 + 6 * kDt + 5'000'000;
  s.pushTrigger(t1);
  pushSequence(s, 0, t1, 6, 20);
  sets = s.takeCompleted();
  REQUIRE(sets.size() == 1);
  CHECK(sets[0]->sequence_id == 1);
  CHECK(tagOf(sets[0]->cameras[0].frames[0]) == 20);
  CHECK(s.counters().sets_completed == 2);
  CHECK(s.counters().frames_unmatched == 0);
  CHECK(s.counters().triggers_incomplete == 0);
}

TEST_CASE("tolerance window edges", "[synchroniser]") {
  // The window of frame i is [t_p + i dt - tol_l dt, t_p + i dt + tol_u dt],
  // both ends inclusive.
  const int i = GENERATE(0, 3, 5);
  const TimestampNs offset = GENERATE(-kTol - 1, -kTol, kTol, kTol + 1);
  const bool inside = offset >= -kTol && offset <= kTol;
  Synchroniser s({"cam"}, options());
  s.setPattern("3+3", 6);
  s.pushTrigger(kT0);
  std::vector<TimestampNs> jitter(6, 0);
  jitter[i] = offset;
  pushSequence(s, 0, kT0, 6, 0, jitter);
  CAPTURE(i, offset);
  CHECK(s.takeCompleted().size() == (inside ? 1u : 0u));
}

TEST_CASE("triggers may arrive before or after their frames", "[synchroniser]") {
  const bool trigger_first = GENERATE(true, false);
  const int trigger_after_frame = GENERATE(0, 2, 6);  // frames pushed before the trigger
  Synchroniser s({"cam"}, options());
  s.setPattern("3+3", 6);
  if (trigger_first) s.pushTrigger(kT0);
  for (int i = 0; i < 6; ++i) {
    if (!trigger_first && i == trigger_after_frame) s.pushTrigger(kT0);
    s.pushFrame(0, frame(kT0 + i * kDt, i));
  }
  if (!trigger_first && trigger_after_frame == 6) s.pushTrigger(kT0);
  const auto sets = s.takeCompleted();
  REQUIRE(sets.size() == 1);
  for (int i = 0; i < 6; ++i) CHECK(tagOf(sets[0]->cameras[0].frames[i]) == i);
}

TEST_CASE("a dropped frame leaves an incomplete sequence that is purged", "[synchroniser]") {
  Synchroniser s({"cam"}, options());
  s.setPattern("3+3", 6);
  const TimestampNs period = 100'000'000;  // one sequence every 100 ms
  // Sequence 0 loses its frame 3; sequences 1..9 are complete.
  for (int seq = 0; seq < 10; ++seq) {
    const TimestampNs t = kT0 + seq * period;
    s.pushTrigger(t);
    for (int i = 0; i < 6; ++i) {
      if (seq == 0 && i == 3) continue;
      s.pushFrame(0, frame(t + i * kDt, seq * 10 + i));
    }
  }
  const auto sets = s.takeCompleted();
  REQUIRE(sets.size() == 9);
  for (std::size_t k = 0; k < sets.size(); ++k) {
    CHECK(sets[k]->trigger_stamp_ns == kT0 + static_cast<TimestampNs>(k + 1) * period);
    CHECK(sets[k]->sequence_id == k);
  }
  // The newest stamp is 950 ms after the first trigger, more than max_age
  // (500 ms): the incomplete trigger and its five frames are gone.
  CHECK(s.counters().triggers_incomplete == 1);
  CHECK(s.counters().frames_unmatched == 5);
  CHECK(s.counters().sets_completed == 9);
}

TEST_CASE("frames without a trigger are purged and counted", "[synchroniser]") {
  Synchroniser s({"cam"}, options());
  s.setPattern("3+3", 6);
  s.pushFrame(0, frame(kT0, 1));
  s.pushFrame(0, frame(kT0 + 400'000'000, 2));
  CHECK(s.counters().frames_unmatched == 0);  // 400 ms < max_age
  s.pushFrame(0, frame(kT0 + 600'000'000, 3));
  CHECK(s.counters().frames_unmatched == 1);
  // A trigger alone ages out the same way.
  s.pushTrigger(kT0 + 700'000'000);
  s.pushTrigger(kT0 + 1'300'000'000);
  CHECK(s.counters().triggers_incomplete == 1);
  CHECK(s.counters().frames_unmatched == 3);
  CHECK(s.takeCompleted().empty());
}

TEST_CASE("two cameras: a set needs both", "[synchroniser]") {
  Synchroniser s({"left", "right"}, options());
  s.setPattern("3+3", 6);
  s.pushTrigger(kT0);
  // The right camera delivers first, slightly later stamps; frames interleave.
  for (int i = 0; i < 6; ++i) s.pushFrame(1, frame(kT0 + i * kDt + 50'000, 100 + i, 12));
  CHECK(s.takeCompleted().empty());
  for (int i = 0; i < 5; ++i) s.pushFrame(0, frame(kT0 + i * kDt, i));
  CHECK(s.takeCompleted().empty());
  s.pushFrame(0, frame(kT0 + 5 * kDt, 5));
  const auto sets = s.takeCompleted();
  REQUIRE(sets.size() == 1);
  REQUIRE(sets[0]->cameras.size() == 2);
  CHECK(sets[0]->cameras[0].camera_id == "left");
  CHECK(sets[0]->cameras[1].camera_id == "right");
  CHECK(sets[0]->cameras[0].bit_depth == 8);
  CHECK(sets[0]->cameras[1].bit_depth == 12);
  for (int i = 0; i < 6; ++i) {
    CHECK(tagOf(sets[0]->cameras[0].frames[i]) == i);
    CHECK(tagOf(sets[0]->cameras[1].frames[i]) == 100 + i);
    CHECK(sets[0]->cameras[1].stamps_ns[i] == kT0 + i * kDt + 50'000);
  }
}

TEST_CASE("a pattern change drops pending work and applies the new length", "[synchroniser]") {
  Synchroniser s({"cam"}, options());
  s.setPattern("3+3", 6);
  s.pushTrigger(kT0);
  pushSequence(s, 0, kT0, 4, 0);  // incomplete
  s.setPattern("3+3 both", 12);
  CHECK(s.counters().triggers_incomplete == 1);
  CHECK(s.counters().frames_unmatched == 4);

  // The remaining frames of the old sequence match nothing now.
  s.pushFrame(0, frame(kT0 + 4 * kDt, 4));
  s.pushFrame(0, frame(kT0 + 5 * kDt, 5));
  const TimestampNs t1 = kT0 + 100'000'000;
  s.pushTrigger(t1);
  pushSequence(s, 0, t1, 6, 20);
  CHECK(s.takeCompleted().empty());  // 6 of 12
  pushSequence(s, 0, t1 + 6 * kDt, 6, 26);
  const auto sets = s.takeCompleted();
  REQUIRE(sets.size() == 1);
  CHECK(sets[0]->pattern_name == "3+3 both");
  REQUIRE(sets[0]->cameras[0].frames.size() == 12);
  for (int i = 0; i < 12; ++i) CHECK(tagOf(sets[0]->cameras[0].frames[i]) == 20 + i);
  CHECK(sets[0]->sequence_id == 0);
}

TEST_CASE("synchroniser rejects bad configuration and indices", "[synchroniser]") {
  CHECK_THROWS_AS(Synchroniser({}, options()), std::invalid_argument);
  SynchroniserOptions o = options();
  o.tolerance_lower = 0.5;
  o.tolerance_upper = 0.5;
  CHECK_THROWS_AS(Synchroniser({"cam"}, o), std::invalid_argument);
  o = options();
  o.image_interval_ns = 0;
  CHECK_THROWS_AS(Synchroniser({"cam"}, o), std::invalid_argument);
  o = options();
  o.tolerance_upper = -0.1;
  CHECK_THROWS_AS(Synchroniser({"cam"}, o), std::invalid_argument);

  Synchroniser s({"cam"}, options());
  CHECK_THROWS_AS(s.setPattern("x", 0), std::invalid_argument);
  CHECK_THROWS_AS(s.pushFrame(1, frame(kT0, 0)), std::out_of_range);
  // Before any pattern nothing matches; frames are simply held and aged out.
  s.pushTrigger(kT0);
  pushSequence(s, 0, kT0, 6, 0);
  CHECK(s.takeCompleted().empty());
}

// Randomized faulty streams: two cameras, 6-frame sequences back to back,
// with dropped frames, duplicated frames, clock jitter inside the tolerance,
// triggers and frames delivered out of order (shuffled within a window),
// and sequences whose images are all lost (a trigger with no images). Every
// emitted set is checked against the truth encoded in the frame ids, every
// sequence whose frames all arrived must be emitted, and the rest must be
// counted as incomplete.
TEST_CASE("randomized faulty streams are never grouped wrongly", "[synchroniser]") {
  const std::uint64_t seed = GENERATE(1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u);
  std::mt19937_64 rng(seed);
  constexpr int kFrames = 6;
  constexpr int kSequences = 200;
  constexpr TimestampNs dt = 33'333'333;
  SynchroniserOptions opts;
  opts.image_interval_ns = dt;
  opts.max_age_ns = 40 * dt;  // far more than the reordering window below
  Synchroniser sync({"top", "left"}, opts);
  sync.setPattern("p", kFrames);

  struct Event {
    bool trigger;
    std::size_t camera;
    TimestampNs stamp;
    std::uint64_t id;  // sequence * 100 + index * 10 + camera
  };
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Event> events;
  std::vector<bool> complete(kSequences, true);
  const TimestampNs t0 = 1'000'000'000'000;
  for (int s = 0; s < kSequences; ++s) {
    const TimestampNs tp = t0 + TimestampNs(s) * kFrames * dt;
    events.push_back({true, 0, tp, 0});
    const bool all_lost = unit(rng) < 0.03;
    for (std::size_t c = 0; c < 2; ++c) {
      for (int i = 0; i < kFrames; ++i) {
        if (all_lost || unit(rng) < 0.03) {  // dropped
          complete[s] = false;
          continue;
        }
        // Jitter within +-0.15 dt (tolerance is 0.2 dt).
        const auto jitter = TimestampNs((unit(rng) - 0.5) * 0.3 * dt);
        const Event e{false, c, tp + i * dt + jitter, std::uint64_t(s * 100 + i * 10 + c)};
        events.push_back(e);
        if (unit(rng) < 0.03) events.push_back(e);  // duplicated delivery
      }
    }
  }
  // Out-of-order delivery: shuffle within windows of 10 events (frames of
  // neighbouring sequences and triggers before or after their frames).
  for (std::size_t begin = 0; begin < events.size(); begin += 10)
    std::shuffle(events.begin() + begin, events.begin() + std::min(begin + 10, events.size()), rng);

  std::vector<int> emitted(kSequences, 0);
  auto check = [&](const std::vector<std::shared_ptr<const ImageSet>>& sets) {
    for (const auto& set : sets) {
      const int s = int((set->trigger_stamp_ns - t0) / (kFrames * dt));
      REQUIRE(set->trigger_stamp_ns == t0 + TimestampNs(s) * kFrames * dt);
      ++emitted[s];
      REQUIRE(set->cameras.size() == 2);
      for (std::size_t c = 0; c < 2; ++c) {
        REQUIRE(set->cameras[c].frames.size() == std::size_t(kFrames));
        for (int i = 0; i < kFrames; ++i) {
          const auto id = set->cameras[c].frames[i].at<std::uint16_t>(0, 0);
          CHECK(id == s * 100 + i * 10 + int(c));  // right sequence, index and camera
        }
      }
    }
  };
  for (const Event& e : events) {
    if (e.trigger) {
      sync.pushTrigger(e.stamp);
    } else {
      Frame f;
      f.image = cv::Mat(1, 1, CV_16UC1, cv::Scalar(double(e.id)));
      f.stamp_ns = e.stamp;
      f.frame_id = e.id;
      sync.pushFrame(e.camera, std::move(f));
    }
    check(sync.takeCompleted());
  }
  // A late trigger far ahead flushes everything pending.
  sync.pushTrigger(t0 + TimestampNs(kSequences + 100) * kFrames * dt);
  check(sync.takeCompleted());

  int expected_complete = 0;
  for (int s = 0; s < kSequences; ++s) {
    INFO("sequence " << s << " complete " << complete[s]);
    CHECK(emitted[s] == (complete[s] ? 1 : 0));  // never twice, never a partial one
    expected_complete += complete[s];
  }
  CHECK(sync.counters().sets_completed == std::uint64_t(expected_complete));
  // (The flushing trigger itself is still pending: it is the newest stamp.)
  CHECK(sync.counters().triggers_incomplete == std::uint64_t(kSequences - expected_complete));
}
