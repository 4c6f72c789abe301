// VersaVIS trigger source: rosserial framing byte for byte, and the serial
// client against a scripted board on a pseudo-terminal pair (garbage,
// checksum errors, time sync, topic negotiation, board hang-up and
// reconnect). Every wait is bounded.
#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <cstdlib>
#include <filesystem>
#include <thread>

#include "sl/drivers/versavis.h"
#include "support/time_scale.h"

using namespace sl::drivers;
namespace rs = sl::drivers::rosserial;
using Bytes = std::vector<std::uint8_t>;
using namespace std::chrono_literals;

namespace {

std::int64_t realtimeNs() {
  timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

// The board side of a pseudo-terminal pair.
class Board {
 public:
  Board() {
    master_ = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
    REQUIRE(master_ >= 0);
    REQUIRE(grantpt(master_) == 0);
    REQUIRE(unlockpt(master_) == 0);
    slave_ = ptsname(master_);
  }
  ~Board() { close(); }
  void close() {
    if (master_ >= 0) ::close(master_);
    master_ = -1;
  }
  const std::string& slavePath() const { return slave_; }
  void send(const Bytes& bytes) {
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(master_, bytes.data() + done, bytes.size() - done);
      REQUIRE((n > 0 || errno == EAGAIN));
      if (n > 0) done += static_cast<std::size_t>(n);
    }
  }
  void publish(std::uint16_t topic, const Bytes& message) { send(rs::encodeFrame(topic, message)); }
  // Raw bytes from the host within `timeout`.
  Bytes readRaw(std::chrono::milliseconds timeout) {
    Bytes out;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      pollfd p{master_, POLLIN, 0};
      if (poll(&p, 1, 10) <= 0) continue;
      std::uint8_t buf[256];
      const ssize_t n = ::read(master_, buf, sizeof buf);
      if (n > 0) out.insert(out.end(), buf, buf + n);
      if (!out.empty()) break;
    }
    return out;
  }
  // Next packet from the host within `timeout` (x10 in sanitizer builds).
  std::optional<rs::Frame> receive(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + sl::test::scaledBound(timeout);
    for (;;) {
      if (auto f = parser_.next()) return f;
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      parser_.feed(readRaw(left));
    }
  }

 private:
  int master_ = -1;
  std::string slave_;
  rs::FrameParser parser_;
};

// A symlink like udev's /dev/versavis, re-pointed when the board reappears.
class DeviceLink {
 public:
  DeviceLink() {
    char tmpl[] = "/tmp/sl_versavis_XXXXXX";
    REQUIRE(mkdtemp(tmpl) != nullptr);
    dir_ = tmpl;
  }
  ~DeviceLink() { std::filesystem::remove_all(dir_); }
  std::string path() const { return (dir_ / "versavis").string(); }
  void pointTo(const std::string& target) {
    const auto tmp = dir_ / "versavis.new";
    std::filesystem::remove(tmp);
    std::filesystem::create_symlink(target, tmp);
    std::filesystem::rename(tmp, dir_ / "versavis");
  }

 private:
  std::filesystem::path dir_;
};

Bytes topicInfo(std::uint16_t id, const std::string& topic,
                const std::string& type = rs::kTimeNumberedType) {
  return rs::encodeTopicInfo({id, topic, type, rs::kTimeNumberedMd5, 512});
}

VersavisConfig testConfig(const std::string& device) {
  VersavisConfig c;
  c.device = device;
  c.baud = 250000;
  c.reconnect_interval = 50ms;
  c.negotiation_retry = 300ms;
  return c;
}

// Calls next() until an event arrives or `timeout` passes.
std::optional<TriggerEvent> nextEvent(VersavisTriggerSource& src,
                                      std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline)
    if (auto e = src.next(50ms)) return e;
  return std::nullopt;
}

// Board side of the negotiation: wait for the topic request, answer with the
// topics and a time request.
void negotiate(Board& board, std::uint16_t projector_id) {
  auto request = board.receive(2000ms);
  REQUIRE(request);
  CHECK(request->topic_id == rs::kTopicPublisher);
  CHECK(request->message.empty());
  board.publish(rs::kTopicPublisher, topicInfo(125, "/versavis/cam0/image_time"));
  board.publish(rs::kTopicPublisher, topicInfo(projector_id, "/versavis/projector/image_time"));
  board.publish(rs::kTopicTime, {});
}

}  // namespace

TEST_CASE("rosserial frames byte for byte") {
  // Topic request of the host: empty message on topic 0.
  CHECK(rs::encodeFrame(0, {}) == Bytes{0xFF, 0xFE, 0x00, 0x00, 0xFF, 0x00, 0x00, 0xFF});
  // std_msgs/Time 1.5 s on topic 10: length 8 (checksum 0xF7), secs 1,
  // nsecs 500000000 = 0x1DCD6500, checksum 255 - (10 + 1 + 0x65 + 0xCD + 0x1D) % 256.
  CHECK(rs::encodeFrame(10, rs::encodeTime(1500000000)) == Bytes{0xFF, 0xFE, 0x08, 0x00, 0xF7, 0x0A,
                                                                 0x00, 0x01, 0x00, 0x00, 0x00, 0x00,
                                                                 0x65, 0xCD, 0x1D, 0xA5});
  // TimeNumbered: secs, nsecs, uint64 number.
  CHECK(rs::encodeTimeNumbered({2, 3, 0x0102030405ull}) ==
        Bytes{2, 0, 0, 0, 3, 0, 0, 0, 5, 4, 3, 2, 1, 0, 0, 0});
  const auto m = rs::decodeTimeNumbered(rs::encodeTimeNumbered({7, 999999999, 42}));
  REQUIRE(m);
  CHECK(m->number == 42);
  CHECK_FALSE(rs::decodeTimeNumbered(Bytes(12, 0)));  // too short
  // TopicInfo: uint16 id, three length-prefixed strings, int32 buffer size.
  const Bytes info = rs::encodeTopicInfo({126, "/t", "a/B", "m", 512});
  CHECK(info == Bytes{126, 0,   2,   0, 0, 0, '/', 't', 3, 0, 0, 0,
                      'a', '/', 'B', 1, 0, 0, 0,   'm', 0, 2, 0, 0});
  const auto decoded = rs::decodeTopicInfo(info);
  REQUIRE(decoded);
  CHECK(decoded->topic_name == "/t");
  CHECK(decoded->message_type == "a/B");
  CHECK_FALSE(rs::decodeTopicInfo(Bytes(info.begin(), info.end() - 1)));
}

TEST_CASE("frame parser: split input, garbage, bad checksums, lone sync bytes") {
  rs::FrameParser parser;
  const Bytes a = rs::encodeFrame(126, rs::encodeTimeNumbered({1, 2, 3}));
  const Bytes b = rs::encodeFrame(10, {});
  Bytes corrupt_msg = a;
  corrupt_msg[10] ^= 0x40;  // message byte changed: message checksum fails
  Bytes corrupt_len = a;
  corrupt_len[4] ^= 0x01;                      // length checksum fails
  Bytes stream{0x00, 0x13, 0xFF, 0x37, 0xFF};  // garbage with lone sync bytes
  for (const Bytes* part :
       std::initializer_list<const Bytes*>{&a, &corrupt_msg, &corrupt_len, &b}) {
    stream.insert(stream.end(), part->begin(), part->end());
    stream.push_back(0xFF);
  }
  Bytes huge{0xFF, 0xFE, 0xFF, 0x7F, 0x81};  // valid length checksum, 32767 bytes: rejected
  stream.insert(stream.end(), huge.begin(), huge.end());
  stream.insert(stream.end(), a.begin(), a.end());
  std::vector<rs::Frame> frames;
  for (std::uint8_t byte : stream) {  // one byte at a time
    parser.feed(std::span<const std::uint8_t>(&byte, 1));
    while (auto f = parser.next()) frames.push_back(*f);
  }
  REQUIRE(frames.size() == 3);
  CHECK(frames[0].topic_id == 126);
  CHECK(frames[1].topic_id == 10);
  CHECK(frames[1].message.empty());
  CHECK(frames[2].topic_id == 126);
  CHECK(parser.checksumErrors() == 3);
  CHECK(parser.garbageBytes() > 0);
}

TEST_CASE("VersaVIS on a pseudo-terminal: negotiation, time sync, triggers, garbage") {
  Board board;
  DeviceLink link;
  link.pointTo(board.slavePath());
  VersavisTriggerSource src(testConfig(link.path()));
  CHECK(src.connected());

  // The host's first bytes are the topic request, verbatim.
  CHECK(board.readRaw(2000ms) == Bytes{0xFF, 0xFE, 0x00, 0x00, 0xFF, 0x00, 0x00, 0xFF});
  board.send({0x12, 0xFF, 0x00, 0x34});  // line noise before the board's answer
  board.publish(rs::kTopicPublisher, topicInfo(125, "/versavis/cam0/image_time"));
  board.publish(rs::kTopicPublisher, topicInfo(126, "/versavis/projector/image_time"));
  board.publish(rs::kTopicTime, {});
  CHECK_FALSE(src.next(100ms));

  // The time request is answered with the host's clock.
  const std::int64_t before = realtimeNs();
  const auto reply = board.receive(2000ms);
  REQUIRE(reply);
  CHECK(reply->topic_id == rs::kTopicTime);
  const auto host_time = rs::decodeTime(reply->message);
  REQUIRE(host_time);
  CHECK(std::llabs(*host_time - before) < 2000000000);

  // Camera channel (ignored), projector triggers, a corrupt one, garbage.
  board.publish(125, rs::encodeTimeNumbered({100, 0, 1}));
  board.publish(126, rs::encodeTimeNumbered({1700000000, 250000000, 11}));
  Bytes corrupt = rs::encodeFrame(126, rs::encodeTimeNumbered({1700000000, 450000000, 12}));
  corrupt[9] ^= 0x01;
  board.send(corrupt);
  board.send({0xFF, 0xFE, 0x01});
  board.publish(126, rs::encodeTimeNumbered({1700000000, 650000000, 13}));

  const auto e1 = nextEvent(src, sl::test::scaledBound(2000ms));
  REQUIRE(e1);
  CHECK(e1->stamp_ns == 1700000000250000000);
  CHECK(e1->sequence_index == 0);
  const auto e2 = nextEvent(src, sl::test::scaledBound(2000ms));
  REQUIRE(e2);
  CHECK(e2->stamp_ns == 1700000000650000000);
  CHECK(e2->sequence_index == 2);  // number 13 - 11: trigger 12 was lost on the wire
  CHECK_FALSE(src.next(50ms));
  const VersavisCounters c = src.counters();
  CHECK(c.triggers == 2);
  CHECK(c.time_requests == 1);
  CHECK(c.checksum_errors >= 1);
  CHECK(c.garbage_bytes >= 4);

  SECTION("board hangs up and comes back: reported once, reconnected, renegotiated") {
    board.close();
    CHECK_THROWS_WITH(nextEvent(src, sl::test::scaledBound(2000ms)),
                      Catch::Contains("board disconnected"));
    CHECK_FALSE(src.connected());
    CHECK_FALSE(src.next(120ms));  // nothing to open yet: retried quietly
    Board again;
    link.pointTo(again.slavePath());
    // The host reconnects inside next(): pump it from a thread meanwhile.
    std::optional<TriggerEvent> e;
    std::thread host([&] { e = nextEvent(src, sl::test::scaledBound(3000ms)); });
    negotiate(again, 130);  // the host asks for the topics again
    again.publish(130, rs::encodeTimeNumbered({1700000001, 0, 500}));
    host.join();
    REQUIRE(e);
    CHECK(e->stamp_ns == 1700000001000000000);
    CHECK(e->sequence_index == 0);
    CHECK(src.counters().connects == 2);
    CHECK(src.counters().disconnects == 1);
  }
}

TEST_CASE("VersaVIS: topic request repeated until the board answers") {
  Board board;
  VersavisTriggerSource src(testConfig(board.slavePath()));
  REQUIRE(board.receive(2000ms));  // first request, unanswered
  const auto t0 = std::chrono::steady_clock::now();
  std::thread host([&] {
    for (int i = 0; i < 20; ++i) src.next(50ms);
  });
  const auto second = board.receive(2000ms);
  host.join();
  REQUIRE(second);
  CHECK(second->topic_id == rs::kTopicPublisher);
  CHECK(std::chrono::steady_clock::now() - t0 >= 250ms);
  CHECK(src.counters().topic_requests >= 2);
}

TEST_CASE("VersaVIS: wrong message type, triggers per sequence, stop, missing device") {
  SECTION("a projector topic of another type is an error naming both types") {
    Board board;
    VersavisTriggerSource src(testConfig(board.slavePath()));
    REQUIRE(board.receive(2000ms));
    board.publish(rs::kTopicPublisher,
                  topicInfo(126, "/versavis/projector/image_time", "std_msgs/Header"));
    CHECK_THROWS_WITH(nextEvent(src, sl::test::scaledBound(2000ms)),
                      Catch::Contains("has type 'std_msgs/Header', expected "
                                      "'versavis/TimeNumbered'"));
  }
  SECTION("every Nth trigger starts a sequence") {
    Board board;
    VersavisConfig cfg = testConfig(board.slavePath());
    cfg.triggers_per_sequence = 3;
    cfg.offset_ns = 1000;
    VersavisTriggerSource src(cfg);
    negotiate(board, 126);
    for (std::uint64_t n = 20; n < 27; ++n)
      board.publish(126, rs::encodeTimeNumbered({10, static_cast<std::uint32_t>(n), n}));
    std::vector<TriggerEvent> events;
    while (auto e = nextEvent(src, 300ms)) events.push_back(*e);
    REQUIRE(events.size() == 3);  // numbers 20, 23, 26
    CHECK(events[1].stamp_ns == 10000000023 + 1000);
    CHECK(events[2].sequence_index == 2);
  }
  SECTION("stop() wakes a blocked next()") {
    Board board;
    VersavisTriggerSource src(testConfig(board.slavePath()));
    std::atomic<bool> returned{false};
    const auto t0 = std::chrono::steady_clock::now();
    std::thread t([&] {
      src.next(sl::test::scaledBound(5000ms));
      returned = true;
    });
    std::this_thread::sleep_for(50ms);
    src.stop();
    t.join();
    CHECK(returned);
    CHECK(std::chrono::steady_clock::now() - t0 < sl::test::scaledBound(2000ms));
    CHECK_FALSE(src.next(10ms));
  }
  SECTION("missing device") {
    CHECK_THROWS_WITH(VersavisTriggerSource(testConfig("/nonexistent/versavis")),
                      "VersaVIS /nonexistent/versavis: cannot open: No such file or directory");
  }
}

TEST_CASE("VersaVIS: triggers received before the projector's start are dropped and counted") {
  Board board;
  VersavisTriggerSource src(testConfig(board.slavePath()));
  negotiate(board, 126);
  for (std::uint64_t n = 1; n <= 3; ++n)
    board.publish(126, rs::encodeTimeNumbered({10, static_cast<std::uint32_t>(n), n}));
  // Reads all three, returns the first.
  const auto first = nextEvent(src, sl::test::scaledBound(2000ms));
  REQUIRE(first);
  std::this_thread::sleep_for(20ms);
  timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  src.dropTriggersBefore(static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec);
  CHECK_FALSE(src.next(100ms));  // numbers 2 and 3 arrived before: dropped
  CHECK(src.counters().triggers_before_start == 2);
  board.publish(126, rs::encodeTimeNumbered({11, 0, 4}));
  const auto after = nextEvent(src, sl::test::scaledBound(2000ms));
  REQUIRE(after);
  CHECK(after->stamp_ns == 11000000000);
}
