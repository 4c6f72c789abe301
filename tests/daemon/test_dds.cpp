// Tests of the sl::dds wrapper and the generated ROS 2 / project types, over
// the loopback configuration (config/cyclonedds-loopback.xml). Every topic
// name contains the pid and a counter, so concurrent runs never interfere;
// every wait is bounded so a failure fails instead of hanging.
#include "support/time_scale.h"
#include <signal.h>
#include <spawn.h>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <future>
#include <memory>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/dds/dds.h"
#include "sl_msgs/msg/CommandReply.h"
#include "sl_msgs/msg/CommandRequest.h"

extern char** environ;

namespace {

using Clock = std::chrono::steady_clock;
using sl::dds::GuardCondition;
using sl::dds::Participant;
using sl::dds::Qos;
using sl::dds::ReadCondition;
using sl::dds::Reader;
using sl::dds::Topic;
using sl::dds::WaitSet;
using sl::dds::Writer;
using Cloud = sensor_msgs_msg_dds__PointCloud2_;

constexpr std::uint32_t kWidth = 1440;
constexpr std::uint32_t kHeight = 1080;
constexpr std::uint32_t kPointStep = 16;  // x, y, z, intensity as float32

// Must run before the first participant is created: Cyclone reads the
// variable when it initialises the domain. SL_TEST_CYCLONEDDS_URI, if set,
// replaces the loopback configuration (to measure another one). The lease is
// scaled in sanitizer builds (scaledDdsLeaseXml).
void useLoopbackConfig() {
  const char* other = std::getenv("SL_TEST_CYCLONEDDS_URI");
  const std::string uri =
      other != nullptr ? other : "file://" SL_SOURCE_DIR "/config/cyclonedds-loopback.xml";
  setenv("CYCLONEDDS_URI", (uri + sl::test::scaledDdsLeaseXml()).c_str(), 1);
}

std::string uniqueTopic(const std::string& name) {
  static std::atomic<int> counter{0};
  return "sl_test/" + std::to_string(getpid()) + "_" + std::to_string(counter++) + "/" + name;
}

// Point i of cloud `seed`: x, y in metres from the pixel position, z varying,
// NaN z every 7th point (invalid pixels), intensity from i and seed.
std::vector<std::uint8_t> makeCloudData(std::uint32_t seed) {
  std::vector<std::uint8_t> data(std::size_t{kWidth} * kHeight * kPointStep);
  for (std::uint32_t row = 0; row < kHeight; ++row) {
    for (std::uint32_t col = 0; col < kWidth; ++col) {
      const std::uint32_t i = row * kWidth + col;
      const float point[4] = {
          (static_cast<float>(col) - kWidth / 2.0f) * 0.001f,
          (static_cast<float>(row) - kHeight / 2.0f) * 0.001f,
          i % 7 == 0 ? NAN : 0.5f + static_cast<float>((i + seed) % 1000) * 0.001f,
          static_cast<float>((i * 31u + seed) % 4096u)};
      std::memcpy(&data[std::size_t{i} * kPointStep], point, sizeof point);
    }
  }
  return data;
}

// A PointCloud2_ whose sequences and strings point into memory this object
// owns (_release = false): nothing allocated by Cyclone, nothing to free.
struct CloudSample {
  explicit CloudSample(std::uint32_t seed) : data(makeCloudData(seed)) {
    static const char* const names[4] = {"x", "y", "z", "intensity"};
    for (int f = 0; f < 4; ++f) {
      fields[f].name = const_cast<char*>(names[f]);
      fields[f].offset = 4u * f;
      fields[f].datatype = sensor_msgs_msg_dds__PointField_Constants_FLOAT32;
      fields[f].count = 1;
    }
    msg.header.stamp.sec = 1700000000;
    msg.header.stamp.nanosec = seed;
    msg.header.frame_id = frame_id.data();
    msg.height = kHeight;
    msg.width = kWidth;
    msg.fields._length = msg.fields._maximum = 4;
    msg.fields._buffer = fields;
    msg.fields._release = false;
    msg.is_bigendian = false;
    msg.point_step = kPointStep;
    msg.row_step = kPointStep * kWidth;
    msg.data._length = msg.data._maximum = static_cast<std::uint32_t>(data.size());
    msg.data._buffer = data.data();
    msg.data._release = false;
    msg.is_dense = false;
  }
  CloudSample(const CloudSample&) = delete;
  CloudSample& operator=(const CloudSample&) = delete;

  std::vector<std::uint8_t> data;
  std::string frame_id = "sl_camera0_optical_frame";
  sensor_msgs_msg_dds__PointField_ fields[4] = {};
  Cloud msg = {};
};

// Checks everything but the data bytes, which the caller compares.
void checkCloudMetadata(const Cloud& got, std::uint32_t seed) {
  CHECK(got.header.stamp.sec == 1700000000);
  CHECK(got.header.stamp.nanosec == seed);
  CHECK(std::string(got.header.frame_id) == "sl_camera0_optical_frame");
  CHECK(got.height == kHeight);
  CHECK(got.width == kWidth);
  REQUIRE(got.fields._length == 4);
  const char* const names[4] = {"x", "y", "z", "intensity"};
  for (std::uint32_t f = 0; f < 4; ++f) {
    CHECK(std::string(got.fields._buffer[f].name) == names[f]);
    CHECK(got.fields._buffer[f].offset == 4 * f);
    CHECK(got.fields._buffer[f].datatype == sensor_msgs_msg_dds__PointField_Constants_FLOAT32);
    CHECK(got.fields._buffer[f].count == 1);
  }
  CHECK_FALSE(got.is_bigendian);
  CHECK(got.point_step == kPointStep);
  CHECK(got.row_step == kPointStep * kWidth);
  CHECK_FALSE(got.is_dense);
  REQUIRE(got.data._length == std::size_t{kWidth} * kHeight * kPointStep);
}

// Point clouds: reliable, keep-last. The writer may block up to 2 s for a
// slow reader before write() reports a timeout.
Qos cloudWriterQos() { return Qos().reliable(DDS_SECS(2)).keepLast(1).volatile_().xcdr1(); }
Qos cloudReaderQos(std::int32_t depth) { return Qos().reliable().keepLast(depth); }

// Waits (bounded) until reader has data.
bool waitForData(const Participant& participant, const sl::dds::Entity& reader,
                 dds_duration_t timeout) {
  WaitSet waitset(participant);
  ReadCondition has_data(reader);
  waitset.attach(has_data);
  return waitset.wait(timeout);
}

// A child process running a hidden test case of this executable; killed if
// still running when this object goes away.
class ChildProcess {
 public:
  explicit ChildProcess(const std::string& test_spec) {
    char exe[4096];
    const ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
    REQUIRE(len > 0);
    exe[len] = '\0';
    std::string spec = test_spec;
    char* argv[] = {exe, spec.data(), nullptr};
    REQUIRE(posix_spawn(&pid_, exe, nullptr, nullptr, argv, environ) == 0);
  }
  ~ChildProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  // Exit status, or -1 if it did not exit within timeout (then it is killed).
  int wait(std::chrono::milliseconds timeout) {
    const auto deadline = Clock::now() + timeout;
    int status = 0;
    while (Clock::now() < deadline) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -1;
  }

 private:
  pid_t pid_ = -1;
};

}  // namespace

namespace {

long minorFaults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

// Writes one byte to each 4 KiB page of [p, p + bytes); returns the minor
// page faults that took. Not instrumented by ThreadSanitizer: each write
// would also touch TSan's shadow of the page, whose first touch faults as
// well, and those faults are TSan's, not the mapping's (under TSan the
// populated mapping counted 8,191 faults and the fresh one 16,399).
__attribute__((no_sanitize_thread)) long faultsWritingPages(unsigned char* p, std::size_t bytes) {
  const long before = minorFaults();
  for (std::size_t i = 0; i < bytes; i += 4096) p[i] = 1;
  return minorFaults() - before;
}

// A writer's keep-last history of 25 MB clouds as Cyclone keeps it: the
// writing thread allocates each cloud's serialized copy, and another thread
// (the one processing acknowledgements) frees the oldest when a fifth
// arrives. Returns the minor page faults per cloud after the first ten.
[[maybe_unused]] double faultsPerCloudInHistory() {  // unused in sanitizer builds
  constexpr std::size_t kCloud = 25'000'000;
  constexpr int kDepth = 4, kWarmUp = 10, kMeasured = 20;
  void* (*volatile allocate)(std::size_t) = std::malloc;  // not elided by the compiler
  std::vector<unsigned char*> history;
  long faults = 0;
  for (int i = 0; i < kWarmUp + kMeasured; ++i) {
    const long before = minorFaults();
    unsigned char* cloud = nullptr;
    std::thread([&] {  // the writer
      cloud = static_cast<unsigned char*>(allocate(kCloud));
      if (cloud) std::memset(cloud, i + 1, kCloud);
    }).join();
    REQUIRE(cloud != nullptr);
    history.push_back(cloud);
    if (history.size() > kDepth) {
      std::thread([&] { std::free(history.front()); }).join();  // acknowledged by all
      history.erase(history.begin());
    }
    if (i >= kWarmUp) faults += minorFaults() - before;
  }
  for (unsigned char* c : history) std::free(c);
  return double(faults) / kMeasured;
}

}  // namespace

#ifndef SL_SANITIZER_BUILD  // the sanitizers' allocators ignore mallopt
TEST_CASE("retainLargeSampleMemory keeps freed clouds' memory for the next ones", "[dds][memory]") {
  REQUIRE(sl::dds::retainLargeSampleMemory());
  // A 25 MB cloud is ~6,100 pages; with glibc's defaults this history
  // page-faults most of every new cloud in again (the heaps of the writer's
  // threads are given back when they empty).
  const double faults = faultsPerCloudInHistory();
  INFO("minor page faults per cloud: " << faults);
  CHECK(faults < 300);
}
#endif

TEST_CASE("populateSharedMemoryMappings fills in the page tables of /dev/shm mappings", "[dds][memory]") {
  // A shared-memory segment as iceoryx maps it: a /dev/shm file, allocated
  // (as iceoryx-prefault leaves RouDi's) and mapped shared, read-write.
  constexpr std::size_t kBytes = std::size_t{32} << 20;  // one chunk of the cloud pool
  const std::string name = "/sl_test_populate_" + std::to_string(getpid());
  const int fd = shm_open(name.c_str(), O_CREAT | O_RDWR | O_EXCL, 0600);
  REQUIRE(fd >= 0);
  REQUIRE(posix_fallocate(fd, 0, kBytes) == 0);
  auto touchAll = [&](unsigned char* p) { return faultsWritingPages(p, kBytes); };
  auto* fresh = static_cast<unsigned char*>(mmap(nullptr, kBytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0));
  REQUIRE(fresh != MAP_FAILED);
  const long fresh_faults = touchAll(fresh);
  munmap(fresh, kBytes);

  auto* populated = static_cast<unsigned char*>(mmap(nullptr, kBytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0));
  REQUIRE(populated != MAP_FAILED);
  CHECK(sl::dds::populateSharedMemoryMappings() >= kBytes);
  const long populated_faults = touchAll(populated);
  munmap(populated, kBytes);
  close(fd);
  shm_unlink(name.c_str());
  INFO("minor page faults writing 32 MiB of /dev/shm: fresh mapping " << fresh_faults
                                                                       << ", populated " << populated_faults);
  CHECK(fresh_faults > 4000);
  CHECK(populated_faults < 100);
}

TEST_CASE("full-size PointCloud2 round trip between two participants", "[dds]") {
  useLoopbackConfig();
  const std::string name = uniqueTopic("points");
  Participant pub_participant;
  Participant sub_participant;
  Topic<Cloud> pub_topic(pub_participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  Topic<Cloud> sub_topic(sub_participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  Writer<Cloud> writer(pub_participant, pub_topic, cloudWriterQos());
  Reader<Cloud> reader(sub_participant, sub_topic, cloudReaderQos(1));
  REQUIRE(writer.waitForReaders(1, DDS_SECS(10) * sl::test::kTimeScale));

  const CloudSample sent(7);
  REQUIRE(writer.write(sent.msg));
  REQUIRE(waitForData(sub_participant, reader, DDS_SECS(10) * sl::test::kTimeScale));

  auto loan = reader.take(4);
  REQUIRE(loan.size() == 1);
  REQUIRE(loan.isValid(0));
  checkCloudMetadata(loan[0], 7);
  CHECK(std::memcmp(loan[0].data._buffer, sent.data.data(), sent.data.size()) == 0);
}

TEST_CASE("writers publish XCDR1 (ROS 2 compatible)", "[dds]") {
  useLoopbackConfig();
  const std::string name = uniqueTopic("xcdr");
  Participant participant;
  Topic<Cloud> topic(participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  // No data representation given: the wrapper adds XCDR1.
  Writer<Cloud> writer(participant, topic, Qos().reliable());
  const dds_data_representation_id_t xcdr2 = DDS_DATA_REPRESENTATION_XCDR2;
  Qos xcdr2_only = Qos().reliable();
  dds_qset_data_representation(const_cast<dds_qos_t*>(xcdr2_only.get()), 1, &xcdr2);

  Reader<Cloud> xcdr2_reader(participant, topic, xcdr2_only);
  Reader<Cloud> xcdr1_reader(participant, topic, Qos().reliable().xcdr1());
  REQUIRE(xcdr1_reader.waitForWriters(1, DDS_SECS(10) * sl::test::kTimeScale));
  // Matching is decided when the reader is created, so this cannot change.
  CHECK(xcdr2_reader.matchedWriters() == 0);
  CHECK(writer.matchedReaders() == 1);
}

TEST_CASE("request/reply round trip", "[dds]") {
  useLoopbackConfig();
  const std::string request_name = uniqueTopic("commandRequest");
  const std::string reply_name = uniqueTopic("commandReply");
  const Qos qos = Qos().reliable().keepLast(16);

  Participant client;
  Topic<sl_msgs_msg_dds__CommandRequest_> client_rq(client, request_name,
                                              sl_msgs_msg_dds__CommandRequest__desc);
  Topic<sl_msgs_msg_dds__CommandReply_> client_rr(client, reply_name, sl_msgs_msg_dds__CommandReply__desc);
  Writer<sl_msgs_msg_dds__CommandRequest_> request_writer(client, client_rq, qos);
  Reader<sl_msgs_msg_dds__CommandReply_> reply_reader(client, client_rr, qos);

  Participant server;
  Topic<sl_msgs_msg_dds__CommandRequest_> server_rq(server, request_name,
                                              sl_msgs_msg_dds__CommandRequest__desc);
  Topic<sl_msgs_msg_dds__CommandReply_> server_rr(server, reply_name, sl_msgs_msg_dds__CommandReply__desc);
  Reader<sl_msgs_msg_dds__CommandRequest_> request_reader(server, server_rq, qos);
  Writer<sl_msgs_msg_dds__CommandReply_> reply_writer(server, server_rr, qos);

  REQUIRE(request_writer.waitForReaders(1, DDS_SECS(10) * sl::test::kTimeScale));
  REQUIRE(reply_writer.waitForReaders(1, DDS_SECS(10) * sl::test::kTimeScale));

  // Client: a stack sample pointing at literals (the writer only reads it).
  sl_msgs_msg_dds__CommandRequest_ request = {};
  request.client_id = const_cast<char*>("test-client");
  request.request_id = 42;
  request.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START;
  request.pattern = const_cast<char*>("3+3");
  request.count = 0;
  REQUIRE(request_writer.write(request));

  // Server: take the request, answer with a heap sample built with Cyclone's
  // allocator and freed with the generated free function.
  REQUIRE(waitForData(server, request_reader, DDS_SECS(10) * sl::test::kTimeScale));
  {
    auto requests = request_reader.take(8);
    REQUIRE(requests.size() == 1);
    REQUIRE(requests.isValid(0));
    const auto& got = requests[0];
    CHECK(std::string(got.client_id) == "test-client");
    CHECK(got.request_id == 42);
    CHECK(got.command == sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START);
    CHECK(std::string(got.pattern) == "3+3");
    CHECK(got.count == 0);

    auto* reply =
        static_cast<sl_msgs_msg_dds__CommandReply_*>(dds_alloc(sizeof(sl_msgs_msg_dds__CommandReply_)));
    reply->client_id = dds_string_dup(got.client_id);
    reply->request_id = got.request_id;
    reply->accepted = true;
    reply->code = sl_msgs_msg_dds__CommandReply_Constants_REPLY_OK;
    reply->reason = dds_string_dup("");
    reply->patterns._length = reply->patterns._maximum = 2;
    reply->patterns._buffer = dds_sequence_string_allocbuf(2);
    reply->patterns._release = true;
    reply->patterns._buffer[0] = dds_string_dup("3+3");
    reply->patterns._buffer[1] = dds_string_dup("gray+phase");
    const bool written = reply_writer.write(*reply);
    sl_msgs_msg_dds__CommandReply__free(reply, DDS_FREE_ALL);
    REQUIRE(written);
  }

  REQUIRE(waitForData(client, reply_reader, DDS_SECS(10) * sl::test::kTimeScale));
  auto replies = reply_reader.take(8);
  REQUIRE(replies.size() == 1);
  REQUIRE(replies.isValid(0));
  const auto& reply = replies[0];
  CHECK(std::string(reply.client_id) == "test-client");
  CHECK(reply.request_id == 42);
  CHECK(reply.accepted);
  CHECK(reply.code == sl_msgs_msg_dds__CommandReply_Constants_REPLY_OK);
  CHECK(std::string(reply.reason).empty());
  REQUIRE(reply.patterns._length == 2);
  CHECK(std::string(reply.patterns._buffer[0]) == "3+3");
  CHECK(std::string(reply.patterns._buffer[1]) == "gray+phase");
}

TEST_CASE("WaitSet::wait returns false after the timeout", "[dds]") {
  useLoopbackConfig();
  Participant participant;
  Topic<sl_msgs_msg_dds__CommandRequest_> topic(participant, uniqueTopic("quiet"),
                                          sl_msgs_msg_dds__CommandRequest__desc);
  Reader<sl_msgs_msg_dds__CommandRequest_> reader(participant, topic);
  ReadCondition has_data(reader);
  WaitSet waitset(participant);
  waitset.attach(has_data, 1);

  const auto start = Clock::now();
  std::vector<dds_attach_t> triggered;
  CHECK_FALSE(waitset.wait(DDS_MSECS(200), &triggered));
  const auto elapsed = Clock::now() - start;
  CHECK(triggered.empty());
  CHECK(elapsed >= std::chrono::milliseconds(190));
  CHECK(elapsed < sl::test::scaledBound(std::chrono::seconds(2)));
  CHECK(reader.take(4).empty());
}

TEST_CASE("GuardCondition wakes a thread waiting on a WaitSet", "[dds]") {
  useLoopbackConfig();
  Participant participant;
  GuardCondition stop(participant);
  WaitSet waitset(participant);
  waitset.attach(stop, 77);

  auto waiter = std::async(std::launch::async, [&waitset] {
    std::vector<dds_attach_t> triggered;
    const auto start = Clock::now();
    const bool woke = waitset.wait(DDS_SECS(10) * sl::test::kTimeScale, &triggered);
    return std::make_tuple(woke, triggered, Clock::now() - start);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  stop.trigger();
  REQUIRE(waiter.wait_for(sl::test::scaledBound(std::chrono::seconds(5))) ==
          std::future_status::ready);
  const auto [woke, triggered, elapsed] = waiter.get();
  CHECK(woke);
  REQUIRE(triggered.size() == 1);
  CHECK(triggered[0] == 77);
  CHECK(elapsed < sl::test::scaledBound(std::chrono::seconds(5)));
  CHECK(stop.triggered());
  stop.reset();
  CHECK_FALSE(stop.triggered());
}

TEST_CASE("failures throw sl::dds::Error naming the call", "[dds]") {
  useLoopbackConfig();
  Participant participant;
  SECTION("illegal topic name") {
    try {
      Topic<Cloud> topic(participant, "bad topic*name", sensor_msgs_msg_dds__PointCloud2__desc);
      FAIL("no exception");
    } catch (const sl::dds::Error& e) {
      const std::string what = e.what();
      INFO(what);
      CHECK(what.find("dds_create_topic(\"bad topic*name\"") != std::string::npos);
      CHECK(what.find(dds_strretcode(e.code())) != std::string::npos);
      CHECK(e.code() == DDS_RETCODE_BAD_PARAMETER);
    }
  }
  SECTION("invalid domain id") {
    try {
      Participant bad(5000);
      FAIL("no exception");
    } catch (const sl::dds::Error& e) {
      const std::string what = e.what();
      INFO(what);
      CHECK(what.find("dds_create_participant(domain 5000)") != std::string::npos);
      CHECK(e.code() < 0);
    }
  }
}

// Two processes: this one reads, a child process (this executable running the
// hidden test case below) writes full-size clouds over the loopback network.
// Proves discovery and large-sample transport between processes and measures
// the rate.
TEST_CASE("full-size clouds between two processes", "[dds][process]") {
  useLoopbackConfig();
  // SL_TEST_IPC_CLOUDS overrides the count for longer measurements.
  const char* clouds_text = std::getenv("SL_TEST_IPC_CLOUDS");
  const int kClouds = clouds_text != nullptr ? std::max(2, std::atoi(clouds_text)) : 20;
  constexpr int kDistinct = 4;  // the child cycles through this many clouds
  const std::string name = uniqueTopic("points_ipc");
  setenv("SL_TEST_CHILD_TOPIC", name.c_str(), 1);
  setenv("SL_TEST_CHILD_COUNT", std::to_string(kClouds).c_str(), 1);
  std::vector<std::vector<std::uint8_t>> expected;
  for (int i = 0; i < kDistinct; ++i) expected.push_back(makeCloudData(i));

  Participant participant;
  Topic<Cloud> topic(participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  Reader<Cloud> reader(participant, topic, Qos().reliable().keepAll());
  ReadCondition has_data(reader);
  WaitSet waitset(participant);
  waitset.attach(has_data);

  ChildProcess child("[.dds_child_publisher]");
  REQUIRE(reader.waitForWriters(1, DDS_SECS(20) * sl::test::kTimeScale));

  int received = 0;
  Clock::time_point first, last;
  const auto deadline = Clock::now() + sl::test::scaledBound(std::chrono::seconds(60));
  while (received < kClouds && Clock::now() < deadline) {
    if (!waitset.wait(DDS_SECS(1))) continue;
    auto loan = reader.take(4);
    for (std::size_t i = 0; i < loan.size(); ++i) {
      if (!loan.isValid(i)) continue;
      last = Clock::now();
      if (received == 0) first = last;
      const Cloud& got = loan[i];
      const std::uint32_t seed = static_cast<std::uint32_t>(received % kDistinct);
      checkCloudMetadata(got, seed);
      CHECK(std::memcmp(got.data._buffer, expected[seed].data(), expected[seed].size()) == 0);
      ++received;
    }
  }
  REQUIRE(received == kClouds);
  CHECK(child.wait(sl::test::scaledBound(std::chrono::seconds(20))) == 0);
  const double seconds = std::chrono::duration<double>(last - first).count();
  std::printf("two processes: %d clouds of %.1f MB, %.1f clouds/s (%.0f MB/s) after the first\n",
              received, expected[0].size() / 1e6, (received - 1) / seconds,
              (received - 1) * expected[0].size() / 1e6 / seconds);
}

// The publishing half of the test above; run only as its child process.
TEST_CASE("child: publish full-size clouds", "[.dds_child_publisher]") {
  useLoopbackConfig();
  const char* topic_name = std::getenv("SL_TEST_CHILD_TOPIC");
  const char* count_text = std::getenv("SL_TEST_CHILD_COUNT");
  REQUIRE(topic_name != nullptr);
  REQUIRE(count_text != nullptr);
  const int count = std::atoi(count_text);

  Participant participant;
  Topic<Cloud> topic(participant, topic_name, sensor_msgs_msg_dds__PointCloud2__desc);
  // Keep-all so that every cloud arrives and the count is deterministic; the
  // writer blocks while the reader catches up.
  // The writer blocks at most 10 s (x10 in sanitizer builds, like the lease).
  Writer<Cloud> writer(participant, topic,
                       Qos().reliable(DDS_SECS(10) * sl::test::kTimeScale).keepAll().xcdr1());
  REQUIRE(writer.waitForReaders(1, DDS_SECS(20) * sl::test::kTimeScale));
  // Prepare the clouds first so that the reader measures transport only.
  std::vector<std::unique_ptr<CloudSample>> clouds;
  for (int i = 0; i < 4; ++i) clouds.push_back(std::make_unique<CloudSample>(i));
  for (int i = 0; i < count; ++i) REQUIRE(writer.write(clouds[i % 4]->msg));
  REQUIRE(dds_wait_for_acks(writer.handle(), DDS_SECS(30) * sl::test::kTimeScale) ==
          DDS_RETCODE_OK);
}
