// IndexedSynchroniser: grouping of software-triggered frames (pattern index
// known), the sibling of the trigger-time Synchroniser.
#include <catch2/catch.hpp>
#include <opencv2/core.hpp>

#include "sl/pipeline/indexed_synchroniser.h"

using namespace sl::pipeline;

namespace {

Frame tagged(int tag, TimestampNs stamp, int bit_depth = 8) {
  Frame f;
  f.image = cv::Mat(1, 1, CV_8UC1, cv::Scalar(tag));
  f.stamp_ns = stamp;
  f.bit_depth = bit_depth;
  return f;
}

}  // namespace

TEST_CASE("indexed grouping: frames in any order complete one set in pattern order") {
  IndexedSynchroniser g({"a", "b"});
  g.begin("P", 3, 1000);
  // Camera b first, indices out of order.
  g.pushFrame(1, 2, tagged(12, 1300));
  g.pushFrame(1, 0, tagged(10, 1100, 12));
  g.pushFrame(0, 0, tagged(0, 1100));
  g.pushFrame(0, 1, tagged(1, 1200));
  g.pushFrame(1, 1, tagged(11, 1200));
  CHECK(g.takeCompleted().empty());
  g.pushFrame(0, 2, tagged(2, 1300));
  const auto sets = g.takeCompleted();
  REQUIRE(sets.size() == 1);
  const ImageSet& s = *sets[0];
  CHECK(s.pattern_name == "P");
  CHECK(s.sequence_id == 0);
  CHECK(s.trigger_stamp_ns == 1000);
  REQUIRE(s.cameras.size() == 2);
  CHECK(s.cameras[0].camera_id == "a");
  CHECK(s.cameras[1].camera_id == "b");
  CHECK(s.cameras[1].bit_depth == 12);
  for (int i = 0; i < 3; ++i) {
    CHECK(s.cameras[0].frames[i].at<std::uint8_t>(0, 0) == i);
    CHECK(s.cameras[1].frames[i].at<std::uint8_t>(0, 0) == 10 + i);
    CHECK(s.cameras[0].stamps_ns[i] == 1100 + 100 * i);
  }
  CHECK(g.counters().sets_completed == 1);
}

TEST_CASE("indexed grouping: stray frames and abandoned sequences are counted") {
  IndexedSynchroniser g({"a"});
  g.pushFrame(0, 0, tagged(0, 1));  // nothing open
  CHECK(g.counters().frames_unmatched == 1);
  g.begin("P", 2, 10);
  g.pushFrame(0, 0, tagged(0, 11));
  g.pushFrame(0, 0, tagged(0, 11));  // a duplicate
  g.pushFrame(0, 5, tagged(0, 12));  // outside the sequence
  CHECK(g.counters().frames_unmatched == 3);
  g.begin("P", 2, 20);  // the open sequence is abandoned: a fault
  CHECK(g.counters().triggers_incomplete == 1);
  CHECK(g.counters().frames_unmatched == 4);
  g.pushFrame(0, 0, tagged(0, 21));
  g.abandon(false);  // a stop cut it short: not counted
  CHECK(g.counters().triggers_incomplete == 1);
  CHECK(g.counters().frames_unmatched == 4);
  CHECK_THROWS_AS(g.pushFrame(1, 0, tagged(0, 1)), std::out_of_range);
  CHECK_THROWS_AS(g.begin("P", 0, 1), std::invalid_argument);
  // Ids run on within a run and start again with the next.
  for (int k = 0; k < 2; ++k) {
    g.begin("Q", 1, 100 + k);
    g.pushFrame(0, 0, tagged(0, 100 + k));
  }
  auto sets = g.takeCompleted();
  REQUIRE(sets.size() == 2);
  CHECK(sets[0]->sequence_id == 0);
  CHECK(sets[1]->sequence_id == 1);
  g.startRun();
  g.begin("Q", 1, 200);
  g.pushFrame(0, 0, tagged(0, 200));
  sets = g.takeCompleted();
  REQUIRE(sets.size() == 1);
  CHECK(sets[0]->sequence_id == 0);
}

TEST_CASE("indexed grouping: a sequence of some cameras completes without the others") {
  IndexedSynchroniser g({"a", "b", "c"});
  g.begin("P", 2, 1000, {2});
  g.pushFrame(2, 0, tagged(20, 1100));
  g.pushFrame(0, 0, tagged(0, 1100));  // not asked for: stray
  CHECK(g.takeCompleted().empty());
  g.pushFrame(2, 1, tagged(21, 1200));
  auto sets = g.takeCompleted();
  REQUIRE(sets.size() == 1);
  REQUIRE(sets[0]->cameras.size() == 1);
  CHECK(sets[0]->cameras[0].camera_id == "c");
  REQUIRE(sets[0]->cameras[0].frames.size() == 2);
  CHECK(sets[0]->cameras[0].frames[1].at<std::uint8_t>(0, 0) == 21);
  CHECK(g.counters().frames_unmatched == 1);
  // Cameras in camera_ids order whatever order they are asked in; all again by default.
  g.begin("P", 1, 2000, {2, 0});
  g.pushFrame(0, 0, tagged(0, 2100));
  g.pushFrame(2, 0, tagged(20, 2100));
  sets = g.takeCompleted();
  REQUIRE(sets.size() == 1);
  REQUIRE(sets[0]->cameras.size() == 2);
  CHECK(sets[0]->cameras[0].camera_id == "a");
  CHECK(sets[0]->cameras[1].camera_id == "c");
  g.begin("P", 1, 3000);
  g.pushFrame(0, 0, tagged(0, 3100));
  g.pushFrame(1, 0, tagged(1, 3100));
  CHECK(g.takeCompleted().empty());
  g.pushFrame(2, 0, tagged(2, 3100));
  CHECK(g.takeCompleted().size() == 1);
  CHECK_THROWS_AS(g.begin("P", 1, 4000, {3}), std::out_of_range);
}
