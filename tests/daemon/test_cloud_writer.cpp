// CloudWriter (dds/include/sl/dds/cloud_writer.h): clouds handed to Cyclone in their
// own memory must be the samples dds_write would have sent, byte for byte,
// and must keep that memory alive exactly as long as Cyclone holds them.
// Linked into test_e2e; the daemon's whole path (another process, the
// network, ROS 2) is covered there and by ros2_interop.
#include "support/time_scale.h"
#include <catch2/catch.hpp>


#include <atomic>
#include <chrono>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <dds/ddsi/ddsi_serdata.h>

#include "sl/dds/cloud_writer.h"
#include "daemon_process.h"
#include "sl/daemon/config.h"
#include "sl/dds/dds.h"
#include "sl/daemon/dds_bridge.h"
#include "sl/daemon/scan_engine.h"

namespace {

using sl::dds::CloudWriter;
using Cloud = CloudWriter::PointCloud2;
namespace dds = sl::dds;

// A topic name no other test (process or case) uses.
std::string uniqueTopic(const std::string& name) {
  static std::atomic<int> counter{0};
  return "sl_test/" + sl::test::uniqueNamespace("cloud_writer") + "_" + std::to_string(counter++) + "/" + name;
}

dds::Qos cloudQos() { return dds::Qos().reliable(DDS_MSECS(200)).keepLast(4).xcdr1(); }

// A cloud message over `data` with a frame id of `frame_length` characters
// (every alignment of what follows it) and `bytes` data bytes (any length,
// not only whole points).
struct Message {
  Message(std::size_t frame_length, std::vector<std::uint8_t> bytes, std::uint32_t stamp)
      : frame(frame_length, 'f'), data(std::move(bytes)) {
    static char x[] = "x", y[] = "y", z[] = "z", in[] = "intensity";
    char* names[4] = {x, y, z, in};
    for (std::uint32_t i = 0; i < 4; ++i) fields[i] = {names[i], 4 * i, 7, 1};
    msg.header.stamp = {static_cast<std::int32_t>(stamp), stamp * 7};
    msg.header.frame_id = frame.data();
    msg.height = 1;
    msg.width = static_cast<std::uint32_t>(data.size() / 16);
    msg.fields = {4, 4, fields, false};
    msg.point_step = 16;
    msg.row_step = 16 * msg.width;
    msg.data = {static_cast<std::uint32_t>(data.size()), static_cast<std::uint32_t>(data.size()),
                data.data(), false};
    msg.is_dense = (stamp % 2) == 0;
  }
  std::string frame;
  std::vector<std::uint8_t> data;
  sensor_msgs_msg_dds__PointField_ fields[4];
  Cloud msg{};
};

std::vector<std::uint8_t> bytesOf(std::size_t n, std::uint32_t seed) {
  std::vector<std::uint8_t> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<std::uint8_t>(i * 31 + seed);
  return v;
}

// The serialized form of what `reader` takes next.
std::string takeBytes(const dds::Reader<Cloud>& reader) {
  ddsi_serdata* d = nullptr;
  dds_sample_info_t info;
  if (dds_takecdr(reader.handle(), &d, 1, &info, DDS_ANY_STATE) != 1) return {};
  std::string bytes(ddsi_serdata_size(d), '\0');
  ddsi_serdata_to_ser(d, 0, bytes.size(), bytes.data());
  ddsi_serdata_unref(d);
  return bytes;
}

}  // namespace

TEST_CASE("a borrowed cloud has dds_write's bytes for every frame id and data length",
          "[dds][cloud_writer]") {
  sl::test::useLoopbackDds();
  const std::string name = uniqueTopic("points");
  dds::Participant participant;
  dds::Topic<Cloud> topic(participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  CloudWriter borrowing(participant, topic, cloudQos(), "");
  INFO(borrowing.whyNotBorrowing());
  REQUIRE(borrowing.borrowing());
  // dds_write's bytes, as a reader in this process takes them.
  dds::Writer<Cloud> plain(participant, topic, cloudQos());
  dds::Reader<Cloud> reader(participant, topic, dds::Qos().reliable().keepLast(1));
  int compared = 0;
  for (std::size_t frame_length = 1; frame_length <= 8; ++frame_length) {
    for (std::size_t bytes : {std::size_t{0}, std::size_t{1}, std::size_t{2}, std::size_t{3},
                              std::size_t{16}, std::size_t{4099}, std::size_t{70001}}) {
      const Message m(frame_length, bytesOf(bytes, static_cast<std::uint32_t>(frame_length)),
                      static_cast<std::uint32_t>(bytes + frame_length));
      REQUIRE(plain.write(m.msg));
      const std::string expected = takeBytes(reader);
      REQUIRE(!expected.empty());
      INFO("frame id of " << frame_length << " characters, " << bytes << " data bytes");
      CHECK(borrowing.borrowedBytes(m.msg) == expected);
      ++compared;
    }
  }
  CHECK(compared == 56);
}

TEST_CASE("borrowed clouds reach a reader whole and their memory is let go afterwards",
          "[dds][cloud_writer]") {
  sl::test::useLoopbackDds();
  const std::string name = uniqueTopic("points");
  dds::Participant writer_participant;
  dds::Participant reader_participant;
  dds::Topic<Cloud> writer_topic(writer_participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  dds::Topic<Cloud> reader_topic(reader_participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  dds::Reader<Cloud> reader(reader_participant, reader_topic, dds::Qos().reliable().keepLast(8));
  std::atomic<int> released{0};
  const std::uint64_t large_copies = CloudWriter::largeCopies();
  constexpr int kClouds = 6;
  std::vector<std::unique_ptr<Message>> sent;
  {
    CloudWriter writer(writer_participant, writer_topic, cloudQos(), "");
    REQUIRE(writer.borrowing());
    REQUIRE(reader.waitForWriters(1, DDS_SECS(10) * sl::test::kTimeScale));
    for (int i = 0; i < kClouds; ++i) {
      // 1 MB and a bit: more than a fragment, not a multiple of 4.
      sent.push_back(std::make_unique<Message>(3 + i, bytesOf((1 << 20) + 16 * i + 3, i), i));
      std::shared_ptr<const void> owner(sent.back().get(), [&released](const void*) { ++released; });
      REQUIRE(writer.write(sent.back()->msg, std::move(owner)));
    }
    auto loan = reader.take(16);  // deserialized through the borrowed sample
    REQUIRE(loan.size() == static_cast<std::size_t>(kClouds));
    for (int i = 0; i < kClouds; ++i) {
      INFO("cloud " << i);
      REQUIRE(loan.isValid(static_cast<std::size_t>(i)));
      const Cloud& got = loan[static_cast<std::size_t>(i)];
      const Message& m = *sent[static_cast<std::size_t>(i)];
      CHECK(std::string(got.header.frame_id) == m.frame);
      CHECK(got.header.stamp.sec == m.msg.header.stamp.sec);
      CHECK(got.is_dense == m.msg.is_dense);
      REQUIRE(got.data._length == m.data.size());
      CHECK(std::memcmp(got.data._buffer, m.data.data(), m.data.size()) == 0);
    }
  }
  // The writer is gone (Cyclone frees its history on its own thread soon
  // after), the reader took everything: nothing holds a cloud.
  const auto deadline = std::chrono::steady_clock::now() + sl::test::scaledBound(std::chrono::seconds(5));
  while (released < kClouds && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  CHECK(released == kClouds);
  // Nothing was converted into a copy of a whole cloud on the way.
  CHECK(CloudWriter::largeCopies() == large_copies);
}

TEST_CASE("a cloud writer told to serialize says why and still delivers", "[dds][cloud_writer]") {
  sl::test::useLoopbackDds();
  const std::string name = uniqueTopic("points");
  dds::Participant participant;
  dds::Topic<Cloud> topic(participant, name, sensor_msgs_msg_dds__PointCloud2__desc);
  CloudWriter writer(participant, topic, cloudQos(), "dds.points_zero_copy is false");
  CHECK_FALSE(writer.borrowing());
  CHECK(writer.whyNotBorrowing() == "dds.points_zero_copy is false");
  CHECK(writer.borrowedBytes(Message(4, bytesOf(32, 1), 1).msg).empty());
  dds::Reader<Cloud> reader(participant, topic, dds::Qos().reliable().keepLast(1));
  const Message m(5, bytesOf(64, 2), 2);
  REQUIRE(writer.write(m.msg, nullptr));
  auto loan = reader.take(1);
  REQUIRE(loan.size() == 1);
  CHECK(std::memcmp(loan[0].data._buffer, m.data.data(), 64) == 0);
}

// Cyclone keeps one key-to-instance map per domain: the second writer's
// probe finds what the first one's left there (the in-process bridges of
// test_bridge.cpp do the same).
TEST_CASE("cloud writers of several participants in one process", "[dds][cloud_writer]") {
  sl::test::useLoopbackDds();
  dds::Participant a;
  dds::Topic<Cloud> ta(a, uniqueTopic("points"), sensor_msgs_msg_dds__PointCloud2__desc);
  CloudWriter wa(a, ta, cloudQos(), "");
  CHECK(wa.borrowing());
  dds::Participant b;
  dds::Topic<Cloud> tb(b, uniqueTopic("points"), sensor_msgs_msg_dds__PointCloud2__desc);
  CloudWriter wb(b, tb, cloudQos(), "");
  CHECK(wb.borrowing());
}

// The bridge's lighter layouts pack each cloud into a buffer that the
// borrowed sample then holds: while readers hold more samples than the
// bridge keeps buffers (8), every cloud must still arrive as packed, none
// overwritten by a later one.
TEST_CASE("decimated clouds borrowed by a reader's history each arrive as packed",
          "[dds][cloud_writer]") {
  sl::test::useLoopbackDds();
  sl::daemon::DdsConfig config;
  config.ns = sl::test::uniqueNamespace("decimated");
  config.points_layout.decimation = 2;
  sl::pipeline::CameraProjectorCalibration calibration;
  calibration.camera = {64, 48, 50, 50, 32, 24};  // width, height, fx, fy, cx, cy
  sl::daemon::DdsBridge bridge(config, "cam", calibration);
  CHECK_FALSE(bridge.resultContents().keeps_clouds);  // packed: the bridge's buffers are held
  dds::Participant participant;
  const std::string topic_name = sl::dds::TopicNames::forNamespace(config.ns).points;
  dds::Topic<Cloud> topic(participant, topic_name, sensor_msgs_msg_dds__PointCloud2__desc);
  dds::Reader<Cloud> reader(participant, topic, dds::Qos().reliable().keepLast(16));
  REQUIRE(reader.waitForWriters(1, DDS_SECS(10) * sl::test::kTimeScale));
  constexpr int kClouds = 12;  // held by the reader until it takes them all
  for (int i = 0; i < kClouds; ++i) {
    auto cloud = std::make_shared<sl::pipeline::PointCloud>();
    cloud->width = 64;
    cloud->height = 48;
    cloud->stamp_ns = 1'000'000'000LL * (i + 1);
    for (int v = 0; v < 48; ++v)
      for (int u = 0; u < 64; ++u)
        cloud->points.push_back({float(u), float(v), float(i), float(u + v)});
    sl::daemon::ScanResult result;
    result.camera_id = "cam";
    result.cloud = cloud;
    result.cloud_unit_m = 1.0;
    bridge.publish(result);
  }
  auto loan = reader.take(32);
  REQUIRE(loan.size() == static_cast<std::size_t>(kClouds));
  for (int i = 0; i < kClouds; ++i) {
    INFO("cloud " << i);
    const Cloud& got = loan[static_cast<std::size_t>(i)];
    REQUIRE(got.width == 32);
    REQUIRE(got.height == 24);
    REQUIRE(got.data._length == 32u * 24u * 16u);
    const float* p = reinterpret_cast<const float*>(got.data._buffer);
    int wrong = 0;
    for (int v = 0; v < 24; ++v)
      for (int u = 0; u < 32; ++u, p += 4)
        wrong += p[0] != float(2 * u) || p[1] != float(2 * v) || p[2] != float(i) || p[3] != float(2 * u + 2 * v);
    CHECK(wrong == 0);
  }
}
