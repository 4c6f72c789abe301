// sl_view's pieces: the CDR reader's errors, the preview decimation, the
// ROS 2 schemas and the MCAP writer's framing (the Node tests check the files
// with @mcap/core; these check what they cannot see: errors, and the bytes
// we choose), and the DDS readers' QoS against the daemon's writers.
#include <catch2/catch.hpp>

#include <fstream>
#include <sstream>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>

#include "common/cdr.h"
#include "common/point_cloud2_cdr.h"
#include "common/mcap_writer.h"
#include "common/ros2_schemas.h"
#include "preview.h"
#include "raw_topics.h"
#include "sl/daemon/dds_bridge.h"

#include <unistd.h>

#include <chrono>
#include <map>
#include <thread>

using sl::tools::CdrError;
using sl::tools::CdrReader;
using sl::tools::CdrWriter;

namespace {

// An organized PointCloud2 of w x h points (x, y, z, intensity float32),
// point (r, c) = (c, r, 1000 r + c, 7).
std::vector<std::uint8_t> cloud(std::uint32_t w, std::uint32_t h) {
  CdrWriter out;
  out.i32(12);
  out.u32(34);
  out.string("frame");
  out.u32(h);
  out.u32(w);
  out.u32(4);
  const char* names[] = {"x", "y", "z", "intensity"};
  for (std::uint32_t i = 0; i < 4; ++i) {
    out.string(names[i]);
    out.u32(4 * i);
    out.u8(7);
    out.u32(1);
  }
  out.boolean(false);
  out.u32(16);
  out.u32(16 * w);
  std::uint8_t* d = out.bytes(std::size_t{16} * w * h);
  for (std::uint32_t r = 0; r < h; ++r)
    for (std::uint32_t c = 0; c < w; ++c) {
      const float p[4] = {float(c), float(r), float(1000 * r + c), 7.f};
      std::memcpy(d + 16 * (r * w + c), p, 16);
    }
  out.boolean(true);
  return out.finish();
}

}  // namespace

TEST_CASE("CdrReader: aligned fields, strings, and errors naming the sample") {
  CdrWriter w;
  w.u8(1);
  w.u32(0xdeadbeef);  // aligned to 4 after the header
  w.u64(42);
  w.string("abc");
  w.f64(2.5);
  auto bytes = w.finish();
  CHECK(bytes[0] == 0);
  CHECK(bytes[1] == 1);
  CHECK((bytes.size() - 4) % 4 == 0);
  CdrReader r(bytes.data(), bytes.size(), "test sample");
  CHECK(r.u8() == 1);
  CHECK(r.u32() == 0xdeadbeef);
  CHECK(r.u64() == 42);
  CHECK(r.string() == "abc");
  CHECK(r.f64() == 2.5);
  CHECK_THROWS_WITH(r.u64(), Catch::Contains("test sample") && Catch::Contains("truncated"));
  const std::uint8_t big_endian[] = {0, 0, 0, 0, 1, 2, 3, 4};
  CHECK_THROWS_WITH(CdrReader(big_endian, sizeof big_endian, "be"),
                    Catch::Contains("be") && Catch::Contains("little-endian"));
}

TEST_CASE("decimateCloud keeps every step-th point of each row and column") {
  const auto in = cloud(10, 7);
  const auto out = sl::view::decimateCloud(
      std::string_view(reinterpret_cast<const char*>(in.data()), in.size()), 4);
  CdrReader r(out.data(), out.size(), "preview");
  CHECK(r.i32() == 12);
  CHECK(r.u32() == 34);
  CHECK(r.string() == "frame");
  CHECK(r.u32() == 2);  // height: rows 0, 4
  CHECK(r.u32() == 3);  // width: columns 0, 4, 8
  REQUIRE(r.u32() == 4);
  for (int i = 0; i < 4; ++i) {
    r.string();
    r.u32();
    r.u8();
    r.u32();
  }
  CHECK_FALSE(r.boolean());
  CHECK(r.u32() == 16);
  CHECK(r.u32() == 48);
  const auto data = r.bytes();
  REQUIRE(data.size() == 6 * 16);
  for (int row = 0; row < 2; ++row)
    for (int col = 0; col < 3; ++col) {
      float p[4];
      std::memcpy(p, data.data() + 16 * (row * 3 + col), 16);
      CHECK(p[0] == float(4 * col));
      CHECK(p[1] == float(4 * row));
      CHECK(p[2] == float(1000 * 4 * row + 4 * col));
    }
  CHECK(r.boolean());
  // A cloud whose data is shorter than width x height points is an error.
  auto broken = cloud(10, 7);
  broken.resize(broken.size() - 40);
  CHECK_THROWS_AS(sl::view::decimateCloud(std::string_view(reinterpret_cast<const char*>(broken.data()), broken.size()), 4),
                  CdrError);
}

TEST_CASE("parsePointCloud2 reads a cloud in place; a short or absurd one is an error") {
  const auto in = cloud(10, 7);
  const sl::tools::PointCloud2View v = sl::tools::parsePointCloud2(in.data(), in.size(), "rt/x/points sample");
  CHECK(v.stampNs() == 12 * 1000000000LL + 34);
  CHECK(v.frame_id == "frame");
  CHECK(v.height == 7);
  CHECK(v.width == 10);
  REQUIRE(v.fields.size() == 4);
  CHECK(v.fields[3].name == "intensity");
  CHECK(v.fields[3].offset == 12);
  CHECK(v.fields[3].datatype == 7);
  CHECK(v.fields[3].count == 1);
  CHECK_FALSE(v.is_bigendian);
  CHECK(v.point_step == 16);
  CHECK(v.row_step == 160);
  CHECK(v.is_dense);
  // The data is a view into the sample, not a copy.
  REQUIRE(v.data.size() == 16 * 70);
  CHECK(reinterpret_cast<const std::uint8_t*>(v.data.data()) > in.data());
  CHECK(reinterpret_cast<const std::uint8_t*>(v.data.data()) + v.data.size() < in.data() + in.size());
  float p[4];
  std::memcpy(p, v.data.data() + 16 * (3 * 10 + 2), 16);
  CHECK(p[2] == 3002.f);

  auto truncated = in;
  truncated.resize(truncated.size() - 40);
  CHECK_THROWS_WITH(sl::tools::parsePointCloud2(truncated.data(), truncated.size(), "rt/x/points sample"),
                    Catch::Contains("rt/x/points sample"));
  // A field count the sample cannot hold is refused before anything is allocated.
  auto absurd = in;
  const std::uint32_t huge = 0x40000000;
  const std::size_t count_at = 4 + 8 + 4 + 6 + 2 + 8;  // after stamp, frame_id "frame", pad, height, width
  std::memcpy(absurd.data() + count_at, &huge, 4);
  CHECK_THROWS_AS(sl::tools::parsePointCloud2(absurd.data(), absurd.size()), CdrError);
}

TEST_CASE("ros2Schema: the standard fields and their dependencies; unknown types named") {
  const auto& pc = sl::tools::ros2Schema("sensor_msgs/msg/PointCloud2");
  CHECK(pc.name == "sensor_msgs/msg/PointCloud2");
  CHECK(pc.definition.rfind("std_msgs/Header header\n", 0) == 0);
  CHECK(pc.definition.find("MSG: std_msgs/Header\n") != std::string::npos);
  CHECK(pc.definition.find("MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n") != std::string::npos);
  CHECK(pc.definition.find("MSG: sensor_msgs/PointField\n") != std::string::npos);
  CHECK(sl::tools::ros2Schema("sensor_msgs/msg/CameraInfo").definition.find("float64[9] k\n") != std::string::npos);
  CHECK_THROWS_WITH(sl::tools::ros2Schema("sensor_msgs/msg/Nope"), Catch::Contains("sensor_msgs/msg/Nope"));
}

// The project's own types: the ROS 2 schema Foxglove and rosbag2 decode
// with must list the members of the DDS IDL the daemon's types are compiled
// from, in order (a member the schema lacks misplaces every field after it).
// Both are generated from ros2/sl_msgs/msg/*.msg (idl/ros2_to_dds_idl.py).
namespace {
std::vector<std::string> idlMembers(const std::string& type) {
  std::ifstream in(std::string(SL_BINARY_DIR) + "/idl/dds_idl/sl_msgs/msg/" + type + ".idl");
  std::string text, line;
  while (std::getline(in, line)) text += line.substr(0, line.find("//")) + "\n";
  const auto begin = text.find("struct " + type + "_ {");
  REQUIRE(begin != std::string::npos);
  const auto end = text.find("};", begin);
  std::vector<std::string> names;
  std::stringstream members(text.substr(text.find('{', begin) + 1, end - text.find('{', begin) - 1));
  for (std::string m; std::getline(members, m, ';');) {
    m.erase(m.find_last_not_of(" \n\t") + 1);
    if (m.find_first_not_of(" \n\t") == std::string::npos) continue;
    std::string name = m.substr(m.find_last_of(" \n\t") + 1);
    names.push_back(name.substr(0, name.find('[')));
  }
  return names;
}
std::vector<std::string> schemaFields(const std::string& type) {
  const std::string& definition = sl::tools::ros2Schema("sl_msgs/msg/" + type).definition;
  std::stringstream lines(definition.substr(0, definition.find("=====")));
  std::vector<std::string> names;
  for (std::string l; std::getline(lines, l);) {
    if (l.empty() || l.find('=') != std::string::npos) continue;  // constants
    names.push_back(l.substr(l.find(' ') + 1));
  }
  return names;
}
}  // namespace

TEST_CASE("ros2Schema: the project's types list the IDL's members in order") {
  for (const std::string type : {"ImageSet", "Status", "ProjectorMaps"}) {
    INFO(type);
    const auto idl = idlMembers(type);
    CHECK(idl.size() > 5);
    CHECK(schemaFields(type) == idl);
  }
}

TEST_CASE("McapWriter: magic at both ends, the footer points at the summary, errors name the file") {
  const std::string path = std::string(SL_BINARY_DIR) + "/tests/view/test_view.mcap";
  {
    sl::tools::McapWriter w(path, {"ros2", "test", "", 64});
    const auto s = w.addSchema("sensor_msgs/msg/PointCloud2", "ros2msg", "uint8 x\n");
    const auto c = w.addChannel(s, "/sl/points", "cdr");
    for (std::uint32_t i = 0; i < 5; ++i) w.write(c, i + 1, 100 + i, 90 + i, "0123456789");
    CHECK(w.messageCount() == 5);
    CHECK_THROWS_WITH(w.write(7, 1, 1, 1, "x"), Catch::Contains(path) && Catch::Contains("channel 7"));
  }
  std::ifstream in(path, std::ios::binary);
  const std::string f((std::istreambuf_iterator<char>(in)), {});
  const std::string magic("\x89MCAP0\r\n", 8);
  REQUIRE(f.size() > 16 + 29);
  CHECK(f.substr(0, 8) == magic);
  CHECK(f.substr(f.size() - 8) == magic);
  // Footer: opcode 0x02, length 20, summary_start, summary_offset_start, crc.
  const std::size_t footer = f.size() - 8 - 29;
  CHECK(f[footer] == 0x02);
  std::uint64_t summary_start, offsets_start;
  std::uint32_t crc;
  std::memcpy(&summary_start, f.data() + footer + 9, 8);
  std::memcpy(&offsets_start, f.data() + footer + 17, 8);
  std::memcpy(&crc, f.data() + footer + 25, 4);
  REQUIRE(summary_start < offsets_start);
  REQUIRE(offsets_start < footer);
  CHECK(f[summary_start] == 0x03);  // the summary opens with the schema
  CHECK(f[offsets_start] == 0x0E);  // then the summary offsets
  CHECK(crc == sl::tools::crc32(std::string_view(f).substr(summary_start, footer + 25 - summary_start)));
  CHECK(sl::tools::crc32("123456789") == 0xCBF43926u);  // the CRC-32 check value
  std::remove(path.c_str());
  CHECK_THROWS_WITH(sl::tools::McapWriter("/nonexistent/dir/x.mcap"), Catch::Contains("/nonexistent/dir/x.mcap"));
  CHECK_THROWS_WITH(sl::tools::McapWriter(path, {"ros2", "t", "brotli", 1}), Catch::Contains("brotli"));
}

// The viewer's readers against the daemon's own writers (DdsBridge with the
// default dds.qos: reliable keep-last): the best-effort keep-last-1 profile
// and the recorder's reliable one both match (no incompatible QoS) and
// receive a published scan's cloud, images and camera_info. DDS on domain 0
// (run in a private network namespace, as the suite is).
TEST_CASE("sl_view's reader QoS matches the daemon's writers", "[view][dds]") {
  sl::daemon::DdsConfig dds;
  dds.ns = "view_qos_" + std::to_string(::getpid());
  dds.publish_images = true;
  sl::pipeline::CameraProjectorCalibration calibration;
  sl::pipeline::PinholeModel& camera = calibration.camera;
  camera.width = 8;
  camera.height = 6;
  camera.fx = camera.fy = 10;
  camera.cx = 4;
  camera.cy = 3;
  sl::daemon::DdsBridge bridge(dds, "cam0", calibration);
  for (const bool best_effort : {true, false}) {
    CAPTURE(best_effort);
    sl::view::RawTopicsOptions options;
    options.ns = dds.ns;
    options.best_effort = best_effort;
    options.only = {"/" + dds.ns + "/points", "/" + dds.ns + "/depth/image",
                    "/" + dds.ns + "/shading/image", "/" + dds.ns + "/camera_info"};
    sl::view::RawTopics raw(options);
    REQUIRE(raw.topics().size() == 4);
    for (std::size_t i = 0; i < raw.topics().size(); ++i) {
      CAPTURE(raw.topics()[i].ros_name);
      for (int k = 0; k < 500 && raw.matchedWriters(i) == 0; ++k)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      CHECK(raw.matchedWriters(i) == 1);
      CHECK(raw.incompatibleWriters(i) == 0);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the writers match us too
    auto cloud = std::make_shared<sl::pipeline::PointCloud>();
    cloud->width = camera.width;
    cloud->height = camera.height;
    cloud->stamp_ns = 1'700'000'000'123'000'000 + (best_effort ? 0 : 1);
    cloud->points.assign(camera.width * camera.height, {1.f, 2.f, 500.f, 100.f});
    sl::daemon::ScanResult result;
    result.camera_id = "cam0";
    result.cloud = cloud;
    std::map<std::string, int> got;
    for (int attempt = 0; attempt < 50 && got.size() < 4; ++attempt) {
      if (attempt % 10 == 0) bridge.publish(result);  // again if the writer had not matched yet
      raw.poll(DDS_MSECS(100), [&](std::shared_ptr<const sl::view::RawSample> s) {
        CdrReader header(s->data(), s->size(), "sample");
        CHECK(header.i32() == 1'700'000'000);
        CHECK(header.u32() == 123'000'000u + (best_effort ? 0u : 1u));
        ++got[raw.topics()[s->topic].ros_name];
      });
    }
    CHECK(got.size() == 4);
    for (std::size_t i = 0; i < raw.topics().size(); ++i) CHECK(raw.samplesLost(i) == 0);
  }
}
