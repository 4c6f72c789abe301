// One text line summing up a sensor_msgs/PointCloud2 field by field, the same
// for any DDS implementation: both interop subscribers (Cyclone DDS with the
// daemon's types, Fast DDS with types generated from ros2_idl/) print it, and
// the test compares the lines. Every field of the message is in the line;
// the data bytes as their length and a 64-bit FNV-1a hash.
#pragma once

#include <cinttypes>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace sl::interop {

struct FieldInfo {
  std::string name;
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;
  std::uint32_t count = 0;
};

struct CloudInfo {
  std::int32_t stamp_sec = 0;
  std::uint32_t stamp_nanosec = 0;
  std::string frame_id;
  std::uint32_t height = 0, width = 0;
  std::vector<FieldInfo> fields;
  bool is_bigendian = false;
  std::uint32_t point_step = 0, row_step = 0;
  const std::uint8_t* data = nullptr;
  std::size_t data_size = 0;
  bool is_dense = false;
};

inline std::uint64_t fnv1a64(const std::uint8_t* data, std::size_t n) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= data[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

// "cloud stamp=S.NNNNNNNNN frame_id=F height=H width=W fields=x:0:7:1,...
//  is_bigendian=0 point_step=P row_step=R data_bytes=N data_fnv1a64=HEX is_dense=0"
inline std::string digestLine(const CloudInfo& c) {
  char buf[256];
  std::string line;
  std::snprintf(buf, sizeof buf, "cloud stamp=%" PRId32 ".%09" PRIu32 " frame_id=", c.stamp_sec,
                c.stamp_nanosec);
  line += buf;
  line += c.frame_id;
  std::snprintf(buf, sizeof buf, " height=%" PRIu32 " width=%" PRIu32 " fields=", c.height,
                c.width);
  line += buf;
  for (std::size_t i = 0; i < c.fields.size(); ++i) {
    const FieldInfo& f = c.fields[i];
    std::snprintf(buf, sizeof buf, "%s%s:%" PRIu32 ":%u:%" PRIu32, i ? "," : "", f.name.c_str(),
                  f.offset, static_cast<unsigned>(f.datatype), f.count);
    line += buf;
  }
  std::snprintf(buf, sizeof buf,
                " is_bigendian=%d point_step=%" PRIu32 " row_step=%" PRIu32
                " data_bytes=%zu data_fnv1a64=%016" PRIx64 " is_dense=%d",
                c.is_bigendian ? 1 : 0, c.point_step, c.row_step, c.data_size,
                fnv1a64(c.data, c.data_size), c.is_dense ? 1 : 0);
  line += buf;
  return line;
}

}  // namespace sl::interop
