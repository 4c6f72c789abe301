// A sensor_msgs/PointCloud2 read in place from its serialized form (XCDR1
// little-endian, as the daemon writes rt/<ns>/points): the header and layout
// parsed, the point data a view into the sample, not copied. For readers
// that take clouds serialized (dds_takecdr) instead of deserializing 25 MB
// into a generated struct: sl_view's preview and sl_dds_bench's in-place
// listener.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "common/cdr.h"

namespace sl::tools {

struct PointFieldCdr {
  std::string name;
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;
  std::uint32_t count = 0;
};

struct PointCloud2View {
  std::int32_t stamp_sec = 0;
  std::uint32_t stamp_nanosec = 0;
  std::string frame_id;
  std::uint32_t height = 0, width = 0;
  std::vector<PointFieldCdr> fields;
  bool is_bigendian = false;
  std::uint32_t point_step = 0, row_step = 0;
  std::string_view data;  // into the sample: valid while the sample is
  bool is_dense = false;

  std::int64_t stampNs() const { return std::int64_t{stamp_sec} * 1000000000 + stamp_nanosec; }
};

// Throws CdrError (naming `what`) if the sample is truncated or its data
// holds fewer than row_step x height bytes, or a row fewer than width points.
inline PointCloud2View parsePointCloud2(const std::uint8_t* sample, std::size_t size,
                                        const std::string& what = "PointCloud2 sample") {
  CdrReader in(sample, size, what);
  PointCloud2View v;
  v.stamp_sec = in.i32();
  v.stamp_nanosec = in.u32();
  v.frame_id = in.string();
  v.height = in.u32();
  v.width = in.u32();
  const std::uint32_t nfields = in.u32();
  // Each field takes at least 13 bytes: a count beyond the sample is malformed.
  if (nfields > size / 13) throw CdrError(what + ": " + std::to_string(nfields) + " fields");
  v.fields.resize(nfields);
  for (PointFieldCdr& f : v.fields) {
    f.name = in.string();
    f.offset = in.u32();
    f.datatype = in.u8();
    f.count = in.u32();
  }
  v.is_bigendian = in.boolean();
  v.point_step = in.u32();
  v.row_step = in.u32();
  v.data = in.bytes();
  v.is_dense = in.boolean();
  if (v.row_step < std::uint64_t{v.width} * v.point_step ||
      v.data.size() < std::uint64_t{v.row_step} * v.height)
    throw CdrError(what + ": " + std::to_string(v.data.size()) + " data bytes for " +
                   std::to_string(v.width) + " x " + std::to_string(v.height) + " points of " +
                   std::to_string(v.point_step) + " bytes (row_step " + std::to_string(v.row_step) +
                   ")");
  return v;
}

}  // namespace sl::tools
