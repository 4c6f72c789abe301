// ScheduleSynchroniser: grouping across pattern switches. A simulated
// projector runs patterns of different lengths and switches at random times
// the way the daemon's request control does (hold at the next sequence
// boundary, stop there, start the new pattern); two cameras deliver frames
// with jitter, latency (hence reordering), drops and duplicates.
#include <algorithm>
#include <cstdint>
#include <map>
#include <queue>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <catch2/catch.hpp>
#include <opencv2/core.hpp>

#include "sl/pipeline/schedule_synchroniser.h"

using namespace sl::pipeline;

namespace {

constexpr TimestampNs kMs = 1'000'000;
constexpr TimestampNs kDt = 10 * kMs;  // image interval
constexpr TimestampNs kT0 = 1'700'000'000'000'000'000;

SynchroniserOptions options() {
  SynchroniserOptions o;
  o.image_interval_ns = kDt;
  o.tolerance_lower = 0.2;
  o.tolerance_upper = 0.2;
  o.max_age_ns = 500 * kMs;
  return o;
}

struct Pattern {
  std::string name;
  int frame_count;
};
const std::vector<Pattern> kPatterns = {{"A", 6}, {"B", 4}, {"C", 3}};

// What a frame's pixels carry: which schedule (projector start), sequence
// within it, pattern index and camera produced it.
cv::Mat tagImage(int schedule, int sequence, int index, int camera) {
  cv::Mat m(1, 4, CV_32SC1);
  m.at<int>(0, 0) = schedule;
  m.at<int>(0, 1) = sequence;
  m.at<int>(0, 2) = index;
  m.at<int>(0, 3) = camera;
  return m;
}

struct Delivery {
  TimestampNs at_ns;   // when the engine receives it
  std::uint64_t order; // ties broken by emission order
  bool is_frame;
  std::size_t camera;
  Frame frame;
  TimestampNs trigger_ns;
  bool operator>(const Delivery& o) const { return std::tie(at_ns, order) > std::tie(o.at_ns, o.order); }
};

struct Outcome {
  std::set<std::pair<int, int>> expected;  // complete sequences (schedule, sequence)
  std::vector<std::shared_ptr<const ImageSet>> emitted;
  std::map<int, std::string> schedule_pattern;
  ScheduleCounters counters;
  int switches = 0, cancels = 0;
};

// One randomized run of about `duration` of projector time.
Outcome simulate(std::uint32_t seed, TimestampNs duration) {
  std::mt19937 rng(seed);
  auto uniform = [&](TimestampNs lo, TimestampNs hi) {
    return std::uniform_int_distribution<TimestampNs>(lo, hi)(rng);
  };
  auto chance = [&](double p) { return std::bernoulli_distribution(p)(rng); };

  Outcome out;
  ScheduleSynchroniser sync({"left", "right"}, options());
  std::priority_queue<Delivery, std::vector<Delivery>, std::greater<>> in_flight;
  std::uint64_t order = 0;

  // Per produced sequence: trigger stamp, frames delivered per (camera, index).
  struct Produced {
    int frame_count = 0;
    TimestampNs trigger_ns = 0;
    bool trigger_delivered = false;
    std::set<std::pair<std::size_t, int>> delivered;
    TimestampNs last_stamp_ns = 0;
  };
  std::map<std::pair<int, int>, Produced> produced;
  std::map<int, TimestampNs> schedule_boundary;  // schedule -> boundary (stopped ones)

  // Projector: schedule `schedule` of `pattern` from start_ns; slot j shows
  // pattern index j % n of sequence j / n until stop_ns.
  int schedule = 0;
  int pattern = 0;
  TimestampNs start_ns = kT0 + 3 * kMs;
  TimestampNs stop_ns = ScheduleSynchroniser::kNoHold;
  std::int64_t next_slot = 0;
  bool projecting = true;
  out.schedule_pattern[0] = kPatterns[0].name;
  sync.startRun(kPatterns[0].name, kPatterns[0].frame_count, kT0);

  // Request control: a pending switch and its boundary; after the stop, the
  // drain until the new pattern starts.
  int pending = -1;
  TimestampNs boundary = 0;
  bool draining = false;
  TimestampNs switch_at = 0;

  auto deliver = [&](TimestampNs stamp, Delivery d) {
    d.order = order++;
    in_flight.push(d);
    if (chance(0.03)) {  // duplicate, later
      d.at_ns += uniform(0, 3 * kDt);
      d.order = order++;
      in_flight.push(std::move(d));
    }
    (void)stamp;
  };

  for (TimestampNs now = kT0; now < kT0 + duration || !in_flight.empty(); now += kMs) {
    // Deliveries due by now, in arrival order.
    while (!in_flight.empty() && in_flight.top().at_ns <= now) {
      Delivery d = in_flight.top();
      in_flight.pop();
      if (d.is_frame) {
        sync.pushFrame(d.camera, std::move(d.frame));
      } else {
        sync.pushTrigger(d.trigger_ns);
      }
      for (auto& set : sync.takeCompleted()) out.emitted.push_back(std::move(set));
    }
    if (now >= kT0 + duration) {
      projecting = false;
      continue;
    }
    // The projector's slots up to now.
    const int n = kPatterns[pattern].frame_count;
    while (projecting && start_ns + next_slot * kDt <= now && start_ns + next_slot * kDt < stop_ns) {
      const int sequence = static_cast<int>(next_slot / n);
      const int index = static_cast<int>(next_slot % n);
      const TimestampNs nominal = start_ns + next_slot * kDt;
      Produced& p = produced[{schedule, sequence}];
      p.frame_count = n;
      if (index == 0) {
        p.trigger_ns = nominal + uniform(-kDt / 50, kDt / 50);
        if (!chance(0.03)) {
          p.trigger_delivered = true;
          Delivery d{nominal + uniform(0, 2 * kDt), 0, false, 0, {}, p.trigger_ns};
          deliver(p.trigger_ns, std::move(d));
        }
      }
      for (std::size_t camera = 0; camera < 2; ++camera) {
        Frame f;
        f.stamp_ns = nominal + uniform(-15 * kDt / 100, 15 * kDt / 100);
        f.image = tagImage(schedule, sequence, index, static_cast<int>(camera));
        f.bit_depth = 8;
        p.last_stamp_ns = std::max(p.last_stamp_ns, f.stamp_ns);
        if (chance(0.02)) continue;  // dropped
        p.delivered.insert({camera, index});
        Delivery d{f.stamp_ns + uniform(kMs, 3 * kDt), 0, true, camera, f, 0};
        deliver(f.stamp_ns, std::move(d));
      }
      ++next_slot;
    }
    // Request control, as the daemon's: a switch holds at the next sequence
    // boundary, the projector stops there (a little late at times), and the
    // new pattern starts after a drain.
    if (draining) {
      if (now >= switch_at) {
        schedule_boundary[schedule] = boundary;
        ++schedule;
        pattern = pending;
        out.schedule_pattern[schedule] = kPatterns[pattern].name;
        sync.switchPattern(kPatterns[pattern].name, kPatterns[pattern].frame_count, now, boundary);
        start_ns = now + uniform(2 * kMs, 5 * kMs);
        stop_ns = ScheduleSynchroniser::kNoHold;
        next_slot = 0;
        projecting = true;
        pending = -1;
        draining = false;
        ++out.switches;
      }
      continue;
    }
    if (pending >= 0 && now >= boundary) {
      // The projector stops late: a few frames after the boundary, at times
      // (a loaded machine) whole sequences of the old pattern, which the
      // switch leaves out.
      stop_ns = boundary + (chance(0.7) ? uniform(0, 3 * kDt / 2) : uniform(0, 8 * kDt));
      draining = true;
      switch_at = stop_ns + uniform(0, 40 * kMs);  // the drain: the last frames read out
      continue;
    }
    if (chance(1.0 / 120)) {
      const int wanted = static_cast<int>(std::uniform_int_distribution<int>(0, 2)(rng));
      if (pending >= 0 && wanted == pattern) {  // back to the running pattern: cancel
        pending = -1;
        sync.holdFrom(ScheduleSynchroniser::kNoHold);
        ++out.cancels;
      } else if (pending >= 0) {
        pending = wanted;  // replaces the pending switch; same boundary
      } else if (wanted != pattern) {
        const TimestampNs period = kPatterns[pattern].frame_count * kDt;
        const TimestampNs last = sync.lastTriggerNs();
        boundary = last > 0 && now >= last ? last + ((now - last) / period + 1) * period : now;
        boundary += uniform(-5, 5);  // integer periods drift from the projector's by a few ns
        pending = wanted;
        sync.holdFrom(boundary);
      }
    }
  }
  // Complete: the trigger and every frame of every camera arrived, and the
  // sequence started before its schedule's boundary (what the projector
  // shows from the boundary on is not part of the request any more).
  for (const auto& [key, p] : produced) {
    const auto b = schedule_boundary.find(key.first);
    const bool before_boundary = b == schedule_boundary.end() || p.last_stamp_ns < b->second - kDt / 5;
    if (p.trigger_delivered && before_boundary &&
        p.delivered.size() == static_cast<std::size_t>(2 * p.frame_count))
      out.expected.insert(key);
  }
  out.counters = sync.counters();
  return out;
}

}  // namespace

TEST_CASE("pattern switches at random times: no set mixes patterns, every complete sequence once",
          "[schedule_synchroniser]") {
  const std::uint32_t seed = GENERATE(range(1u, 13u));
  const Outcome out = simulate(seed, 4'000 * kMs);
  INFO("seed " << seed << ": " << out.switches << " switches, " << out.cancels << " cancelled, "
               << out.expected.size() << " complete sequences, " << out.emitted.size() << " sets");
  REQUIRE(out.switches >= 5);

  std::multiset<std::pair<int, int>> emitted;
  std::uint64_t previous_id = 0;
  for (std::size_t k = 0; k < out.emitted.size(); ++k) {
    const ImageSet& set = *out.emitted[k];
    REQUIRE(set.cameras.size() == 2);
    const int schedule = set.cameras[0].frames.at(0).at<int>(0, 0);
    const int sequence = set.cameras[0].frames.at(0).at<int>(0, 1);
    // One pattern, one sequence, frames in pattern order, both cameras.
    CHECK(set.pattern_name == out.schedule_pattern.at(schedule));
    for (std::size_t c = 0; c < 2; ++c) {
      const CameraImages& images = set.cameras[c];
      REQUIRE(images.frames.size() == static_cast<std::size_t>(std::find_if(
                                          kPatterns.begin(), kPatterns.end(),
                                          [&](const Pattern& p) { return p.name == set.pattern_name; })
                                          ->frame_count));
      for (std::size_t i = 0; i < images.frames.size(); ++i) {
        const cv::Mat& tag = images.frames[i];
        CHECK(tag.at<int>(0, 0) == schedule);
        CHECK(tag.at<int>(0, 1) == sequence);
        CHECK(tag.at<int>(0, 2) == static_cast<int>(i));
        CHECK(tag.at<int>(0, 3) == static_cast<int>(c));
      }
    }
    if (k > 0) CHECK(set.sequence_id == previous_id + 1);  // ids run on across switches
    previous_id = set.sequence_id;
    emitted.insert({schedule, sequence});
  }
  // Exactly once each, and exactly the complete ones.
  for (const auto& key : emitted) CHECK(emitted.count(key) == 1);
  const std::set<std::pair<int, int>> unique(emitted.begin(), emitted.end());
  std::vector<std::pair<int, int>> missing, extra;
  std::set_difference(out.expected.begin(), out.expected.end(), unique.begin(), unique.end(),
                      std::back_inserter(missing));
  std::set_difference(unique.begin(), unique.end(), out.expected.begin(), out.expected.end(),
                      std::back_inserter(extra));
  INFO("first missing: " << (missing.empty() ? -1 : missing[0].first) << "/"
                         << (missing.empty() ? -1 : missing[0].second));
  CHECK(missing.empty());
  CHECK(extra.empty());
  CHECK(out.counters.sets_completed == out.emitted.size());
  // Drops leave sequences incomplete; those are counted, not lost silently.
  CHECK(out.counters.triggers_incomplete + out.counters.frames_unmatched > 0);
}

TEST_CASE("a held switch boundary keeps the next sequence out; cancelling releases it",
          "[schedule_synchroniser]") {
  ScheduleSynchroniser sync({"cam"}, options());
  sync.startRun("A", 2, kT0);
  auto push = [&](TimestampNs trigger, int n) {
    sync.pushTrigger(trigger);
    for (int i = 0; i < n; ++i) {
      Frame f;
      f.stamp_ns = trigger + i * kDt;
      f.image = cv::Mat(1, 1, CV_8UC1, cv::Scalar(i));
      sync.pushFrame(0, std::move(f));
    }
  };
  push(kT0 + kMs, 2);
  CHECK(sync.takeCompleted().size() == 1);
  CHECK(sync.lastTriggerNs() == kT0 + kMs);
  sync.holdFrom(kT0 + kMs + 2 * kDt);
  push(kT0 + kMs + 2 * kDt, 2);  // at the boundary: belongs to no set
  CHECK(sync.takeCompleted().empty());
  CHECK(sync.counters().stamps_outside == 3);
  sync.holdFrom(ScheduleSynchroniser::kNoHold);  // switch cancelled
  push(kT0 + kMs + 4 * kDt, 2);
  const auto sets = sync.takeCompleted();
  REQUIRE(sets.size() == 1);
  CHECK(sets[0]->sequence_id == 1);
  CHECK(sets[0]->pattern_name == "A");
}

TEST_CASE("ending a run counts what it held only when frames were lost", "[schedule_synchroniser]") {
  for (const bool count_pending : {false, true}) {
    ScheduleSynchroniser sync({"cam"}, options());
    sync.startRun("A", 3, kT0);
    sync.pushTrigger(kT0 + kMs);
    Frame f;
    f.stamp_ns = kT0 + kMs;
    f.image = cv::Mat(1, 1, CV_8UC1, cv::Scalar(0));
    sync.pushFrame(0, std::move(f));
    sync.endRun(count_pending);
    CHECK_FALSE(sync.running());
    CHECK(sync.counters().triggers_incomplete == (count_pending ? 1u : 0u));
    CHECK(sync.counters().frames_unmatched == (count_pending ? 1u : 0u));
    sync.pushTrigger(kT0 + 2 * kDt);  // no run: outside every schedule
    CHECK(sync.counters().stamps_outside == 1);
    // A new run numbers its sequences from 0 again.
    sync.startRun("B", 1, kT0 + 10 * kDt);
    sync.pushTrigger(kT0 + 11 * kDt);
    Frame g;
    g.stamp_ns = kT0 + 11 * kDt;
    g.image = cv::Mat(1, 1, CV_8UC1, cv::Scalar(0));
    sync.pushFrame(0, std::move(g));
    const auto sets = sync.takeCompleted();
    REQUIRE(sets.size() == 1);
    CHECK(sets[0]->sequence_id == 0);
    CHECK(sets[0]->pattern_name == "B");
  }
}

TEST_CASE("a boundary a few ns off the projector's schedule cuts no sequence into a fault",
          "[schedule_synchroniser]") {
  // The engine computes the boundary as last trigger + k * frame_count * dt
  // in whole ns; the projector's own clock rounds differently. The sequence
  // starting at the boundary, stamped a little before it, is not the old
  // schedule's: it is left out, not counted as incomplete.
  for (const TimestampNs off : {-3, 2, 1000}) {
    ScheduleSynchroniser sync({"cam"}, options());
    sync.startRun("A", 2, kT0);
    auto frame = [](TimestampNs stamp) {
      Frame f;
      f.stamp_ns = stamp;
      f.image = cv::Mat(1, 1, CV_8UC1, cv::Scalar(0));
      return f;
    };
    const TimestampNs t1 = kT0 + kMs, next = t1 + 2 * kDt;
    sync.pushTrigger(t1);
    sync.pushFrame(0, frame(t1));
    sync.holdFrom(next + off);
    sync.pushFrame(0, frame(t1 + kDt));
    sync.pushTrigger(next);  // the old pattern's next sequence, before the stop
    sync.pushFrame(0, frame(next));
    sync.switchPattern("B", 1, next + 5 * kMs, next + off);
    CHECK(sync.takeCompleted().size() == 1);
    // Long after: the old schedule retires.
    const TimestampNs later = next + options().max_age_ns + 10 * kDt;
    sync.pushTrigger(later);
    sync.pushFrame(0, frame(later));
    const auto sets = sync.takeCompleted();
    REQUIRE(sets.size() == 1);
    CHECK(sets[0]->pattern_name == "B");
    INFO("boundary " << off << " ns after the next sequence's start");
    CHECK(sync.counters().triggers_incomplete == 0);
    CHECK(sync.counters().frames_unmatched == 0);
  }
}
