// BoundedQueue: the two overflow policies and shutdown. Every wait is bounded
// (a future with a timeout), so a deadlock fails the test instead of hanging.
#include <catch2/catch.hpp>

#include <chrono>
#include <future>
#include <thread>

#include "sl/daemon/bounded_queue.h"
#include "support/time_scale.h"

using namespace std::chrono_literals;
using sl::daemon::BoundedQueue;
using sl::daemon::Overflow;

namespace {

template <typename T>
bool finishes(std::future<T>& f) {
  return f.wait_for(sl::test::scaledBound(10s)) == std::future_status::ready;
}

}  // namespace

TEST_CASE("drop oldest: a full queue keeps the newest elements and counts the dropped ones") {
  BoundedQueue<int> q(3);
  CHECK(q.push(1));
  CHECK(q.push(2));
  CHECK(q.push(3));
  CHECK_FALSE(q.push(4));  // 1 dropped
  CHECK_FALSE(q.push(5));  // 2 dropped
  CHECK(q.size() == 3);
  CHECK(q.dropped() == 2);
  CHECK(q.pop(0ms) == 3);
  CHECK(q.tryPop() == 4);
  CHECK(q.pop(0ms) == 5);
  CHECK_FALSE(q.tryPop());
  CHECK(q.dropped() == 2);
}

TEST_CASE("wait for room: a full queue makes the producer wait, never drops") {
  BoundedQueue<int> q(2, Overflow::kWaitForRoom);
  CHECK(q.push(1));
  CHECK(q.push(2));
  auto producer = std::async(std::launch::async, [&] { return q.push(3); });
  // Still waiting after a while (the queue is full and nobody pops).
  CHECK(producer.wait_for(50ms) == std::future_status::timeout);
  CHECK(q.size() == 2);
  CHECK(q.pop(0ms) == 1);  // makes room
  REQUIRE(finishes(producer));
  CHECK(producer.get());
  CHECK(q.pop(0ms) == 2);
  CHECK(q.pop(0ms) == 3);
  CHECK(q.dropped() == 0);
}

TEST_CASE("close wakes a waiting consumer and a waiting producer; what is left still drains") {
  SECTION("consumer") {
    BoundedQueue<int> q(2);
    auto consumer = std::async(std::launch::async, [&] { return q.pop(60s); });
    std::this_thread::sleep_for(10ms);
    q.close();
    REQUIRE(finishes(consumer));
    CHECK_FALSE(consumer.get());
  }
  SECTION("producer") {
    BoundedQueue<int> q(1, Overflow::kWaitForRoom);
    CHECK(q.push(1));
    auto producer = std::async(std::launch::async, [&] { return q.push(2); });
    std::this_thread::sleep_for(10ms);
    q.close();
    REQUIRE(finishes(producer));
    CHECK_FALSE(producer.get());  // dropped, and counted
    CHECK(q.dropped() == 1);
    CHECK(q.pop(60s) == 1);       // left over: drained without waiting
    CHECK_FALSE(q.pop(60s));      // closed and empty: at once
  }
  SECTION("push after close") {
    BoundedQueue<int> q(4);
    q.close();
    CHECK_FALSE(q.push(7));
    CHECK(q.dropped() == 1);
    CHECK(q.size() == 0);
  }
}

TEST_CASE("clear drops what is queued, counts it, and makes room for a waiting producer") {
  BoundedQueue<int> q(2, Overflow::kWaitForRoom);
  CHECK(q.push(1));
  CHECK(q.push(2));
  auto producer = std::async(std::launch::async, [&] { return q.push(3); });
  CHECK(producer.wait_for(20ms) == std::future_status::timeout);
  CHECK(q.clear() == 2);
  REQUIRE(finishes(producer));
  CHECK(producer.get());
  CHECK(q.dropped() == 2);
  CHECK(q.tryPop() == 3);
}

TEST_CASE("many producers and consumers: every element is popped once or counted as dropped") {
  BoundedQueue<int> q(8);
  constexpr int kPerProducer = 2000;
  std::atomic<long> popped_sum{0}, popped{0};
  std::atomic<bool> done{false};
  std::vector<std::thread> consumers;
  for (int c = 0; c < 2; ++c)
    consumers.emplace_back([&] {
      while (!done || q.size() > 0)
        if (auto v = q.pop(1ms)) {
          popped_sum += *v;
          ++popped;
        }
    });
  std::vector<std::thread> producers;
  for (int p = 0; p < 3; ++p)
    producers.emplace_back([&] {
      for (int i = 1; i <= kPerProducer; ++i) q.push(1);
    });
  for (auto& t : producers) t.join();
  done = true;
  for (auto& t : consumers) t.join();
  CHECK(popped.load() + static_cast<long>(q.dropped()) == 3 * kPerProducer);
  CHECK(popped_sum.load() == popped.load());
}
