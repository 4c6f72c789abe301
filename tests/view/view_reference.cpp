// The reference side of the ROS 2 wire-format check (tests/view): receives
// the daemon's clouds, images, camera info and status through Cyclone DDS
// with the project's own IDL types (Cyclone deserializes them) and writes
// every field as JSON, the point / pixel data as .bin files, one pair per
// sample, named <topic>_<sec>_<nanosec>. tools/sl_view/test/wire_check.mjs
// then decodes the same samples, taken from sl_view or from an MCAP file,
// with Foxglove's ROS 2 deserializer and compares everything.
//
// usage: view_reference --ns NS --out DIR --count N [--timeout S]
// Prints "ready" once every reader is matched with the daemon's writers;
// exits 0 after N clouds (and the images of their scans), 1 on timeout;
// --count 0: takes everything until the timeout (or SIGTERM), then exits 0.
#include <json/json.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <iostream>
#include <string>
#include <thread>

#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/dds/dds.h"
#include "sl_msgs/msg/Status.h"

namespace {

using Cloud = sensor_msgs_msg_dds__PointCloud2_;
using Image = sensor_msgs_msg_dds__Image_;
using Info = sensor_msgs_msg_dds__CameraInfo_;
using Status = sl_msgs_msg_dds__Status_;
namespace dds = sl::dds;

Json::Value time(const builtin_interfaces_msg_dds__Time_& t) {
  Json::Value v;
  v["sec"] = t.sec;
  v["nanosec"] = t.nanosec;
  return v;
}
Json::Value header(const std_msgs_msg_dds__Header_& h) {
  Json::Value v;
  v["stamp"] = time(h.stamp);
  v["frame_id"] = h.frame_id ? h.frame_id : "";
  return v;
}
Json::Value strings(const dds_sequence_string& s) {
  Json::Value v(Json::arrayValue);
  for (std::uint32_t i = 0; i < s._length; ++i) v.append(s._buffer[i]);
  return v;
}

std::string stem(const std::string& dir, const char* topic, const builtin_interfaces_msg_dds__Time_& t) {
  return dir + "/" + topic + "_" + std::to_string(t.sec) + "_" + std::to_string(t.nanosec);
}

void save(const std::string& stem, Json::Value v, const void* data, std::size_t size) {
  if (data != nullptr) {
    std::ofstream(stem + ".bin", std::ios::binary).write(static_cast<const char*>(data), size);
    v["data_length"] = Json::UInt64(size);
  }
  std::ofstream(stem + ".json") << v;
}

Json::Value imageJson(const Image& m) {
  Json::Value v;
  v["header"] = header(m.header);
  v["height"] = m.height;
  v["width"] = m.width;
  v["encoding"] = m.encoding ? m.encoding : "";
  v["is_bigendian"] = m.is_bigendian;
  v["step"] = m.step;
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  // A reader of full clouds keeps their memory (README, "Memory of large
  // samples"): with glibc's defaults each cloud was page-faulted in again,
  // this keep-all reader fell behind the daemon's history of 4 and lost
  // samples that sl_view got.
  sl::dds::retainLargeSampleMemory();
  std::string ns = "sl", out;
  int count = 1;
  double timeout_s = 60;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--ns") ns = argv[i + 1];
    else if (a == "--out") out = argv[i + 1];
    else if (a == "--count") count = std::atoi(argv[i + 1]);
    else if (a == "--timeout") timeout_s = std::atof(argv[i + 1]);
    else {
      std::cerr << "view_reference: unknown option " << a << "\n";
      return 2;
    }
  }
  if (out.empty()) {
    std::cerr << "usage: view_reference --ns NS --out DIR --count N [--timeout S]\n";
    return 2;
  }
  dds::Participant p(0);
  dds::Topic<Cloud> points_t(p, "rt/" + ns + "/points", sensor_msgs_msg_dds__PointCloud2__desc);
  dds::Topic<Image> depth_t(p, "rt/" + ns + "/depth/image", sensor_msgs_msg_dds__Image__desc);
  dds::Topic<Image> shading_t(p, "rt/" + ns + "/shading/image", sensor_msgs_msg_dds__Image__desc);
  dds::Topic<Info> info_t(p, "rt/" + ns + "/camera_info", sensor_msgs_msg_dds__CameraInfo__desc);
  dds::Topic<Status> status_t(p, "rt/" + ns + "/status", sl_msgs_msg_dds__Status__desc);
  // Keep-all: nothing is overwritten while this program writes files (the
  // check asks for every sample the bridge or a recording saw).
  const auto qos = dds::Qos().reliable().keepAll();
  dds::Reader<Cloud> points(p, points_t, qos);
  dds::Reader<Image> depth(p, depth_t, qos);
  dds::Reader<Image> shading(p, shading_t, qos);
  dds::Reader<Info> info(p, info_t, qos);
  dds::Reader<Status> status(p, status_t, dds::Qos().reliable().transientLocal().keepAll());
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!(points.matchedWriters() && depth.matchedWriters() && shading.matchedWriters() &&
           info.matchedWriters() && status.matchedWriters())) {
    if (std::chrono::steady_clock::now() > deadline) {
      std::cerr << "view_reference: daemon writers not matched (publish_images on?)\n";
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::printf("ready\n");
  std::fflush(stdout);
  int clouds = 0, depths = 0, shadings = 0, infos = 0;
  // Once everything is in, status samples are taken for a while longer (the
  // daemon publishes one when the scan ends).
  std::optional<std::chrono::steady_clock::time_point> linger;
  while (std::chrono::steady_clock::now() < deadline) {
    bool any = false;
    for (auto loan = points.take(4); !loan.empty(); loan = points.take(4)) {
      any = true;
      for (std::size_t i = 0; i < loan.size(); ++i) {
        if (!loan.isValid(i)) continue;
        const Cloud& m = loan[i];
        Json::Value v;
        v["header"] = header(m.header);
        v["height"] = m.height;
        v["width"] = m.width;
        v["fields"] = Json::Value(Json::arrayValue);
        for (std::uint32_t f = 0; f < m.fields._length; ++f) {
          Json::Value j;
          j["name"] = m.fields._buffer[f].name;
          j["offset"] = m.fields._buffer[f].offset;
          j["datatype"] = m.fields._buffer[f].datatype;
          j["count"] = m.fields._buffer[f].count;
          v["fields"].append(j);
        }
        v["is_bigendian"] = m.is_bigendian;
        v["point_step"] = m.point_step;
        v["row_step"] = m.row_step;
        v["is_dense"] = m.is_dense;
        save(stem(out, "points", m.header.stamp), v, m.data._buffer, m.data._length);
        ++clouds;
      }
    }
    for (auto* r : {&depth, &shading}) {
      for (auto loan = r->take(4); !loan.empty(); loan = r->take(4)) {
        any = true;
        for (std::size_t i = 0; i < loan.size(); ++i) {
          if (!loan.isValid(i)) continue;
          const Image& m = loan[i];
          save(stem(out, r == &depth ? "depth" : "shading", m.header.stamp), imageJson(m),
               m.data._buffer, m.data._length);
          ++(r == &depth ? depths : shadings);
        }
      }
    }
    for (auto loan = info.take(4); !loan.empty(); loan = info.take(4)) {
      any = true;
      for (std::size_t i = 0; i < loan.size(); ++i) {
        if (!loan.isValid(i)) continue;
        const Info& m = loan[i];
        Json::Value v;
        v["header"] = header(m.header);
        v["height"] = m.height;
        v["width"] = m.width;
        v["distortion_model"] = m.distortion_model ? m.distortion_model : "";
        for (std::uint32_t k = 0; k < m.d._length; ++k) v["d"].append(m.d._buffer[k]);
        for (double x : m.k) v["k"].append(x);
        for (double x : m.r) v["r"].append(x);
        for (double x : m.p) v["p"].append(x);
        v["binning_x"] = m.binning_x;
        v["binning_y"] = m.binning_y;
        v["roi"]["x_offset"] = m.roi.x_offset;
        v["roi"]["y_offset"] = m.roi.y_offset;
        v["roi"]["height"] = m.roi.height;
        v["roi"]["width"] = m.roi.width;
        v["roi"]["do_rectify"] = m.roi.do_rectify;
        save(stem(out, "camera_info", m.header.stamp), v, nullptr, 0);
        ++infos;
      }
    }
    for (auto loan = status.take(16); !loan.empty(); loan = status.take(16)) {
      any = true;
      for (std::size_t i = 0; i < loan.size(); ++i) {
        if (!loan.isValid(i)) continue;
        const Status& m = loan[i];
        Json::Value v;
        v["stamp"] = time(m.stamp);
        v["state"] = static_cast<int>(m.state);
        v["pattern"] = m.pattern;
        v["scans_done"] = Json::UInt64(m.scans_done);
        v["scans_requested"] = Json::UInt64(m.scans_requested);
        v["scan_rate_hz"] = m.scan_rate_hz;
        v["frames_dropped"] = Json::UInt64(m.frames_dropped);
        v["sets_dropped"] = Json::UInt64(m.sets_dropped);
        v["sets_incomplete"] = Json::UInt64(m.sets_incomplete);
        v["frames_overflow"] = Json::UInt64(m.frames_overflow);
        v["frames_unmatched"] = Json::UInt64(m.frames_unmatched);
        v["sets_overflow"] = Json::UInt64(m.sets_overflow);
        v["writes_timed_out"] = Json::UInt64(m.writes_timed_out);
        v["sets_not_recorded"] = Json::UInt64(m.sets_not_recorded);
        v["recording"] = m.recording;
        v["sets_recorded"] = Json::UInt64(m.sets_recorded);
        v["last_error"] = m.last_error;
        v["patterns"] = strings(m.patterns);
        v["trigger"] = static_cast<int>(m.trigger);
        v["cameras"] = strings(m.cameras);
        v["motion_compensation"] = m.motion_compensation;
        v["start_at"] = time(m.start_at);
        v["frame_rate_hz"] = m.frame_rate_hz;
        save(stem(out, "status", m.stamp), v, nullptr, 0);
      }
    }
    if (count > 0 && !linger && clouds >= count && depths >= count && shadings >= count && infos >= count)
      linger = std::chrono::steady_clock::now() + std::chrono::milliseconds(1500);
    if (linger && std::chrono::steady_clock::now() > *linger) {
      std::printf("done: %d clouds, %d depth, %d shading, %d camera_info\n", clouds, depths,
                  shadings, infos);
      return 0;
    }
    if (!any) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (count == 0) return 0;
  std::cerr << "view_reference: timeout: " << clouds << " clouds, " << depths << " depth, "
            << shadings << " shading, " << infos << " camera_info of " << count << "\n";
  return 1;
}
