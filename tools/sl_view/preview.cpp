#include "preview.h"

#include <cstring>
#include <string>

#include "common/cdr.h"

namespace sl::view {

std::vector<std::uint8_t> decimateCloud(std::string_view cdr, int step) {
  if (step < 1) throw tools::CdrError("decimation step must be >= 1");
  tools::CdrReader in(reinterpret_cast<const std::uint8_t*>(cdr.data()), cdr.size(),
                      "PointCloud2 sample");
  tools::CdrWriter out;
  out.i32(in.i32());      // header.stamp.sec
  out.u32(in.u32());      // header.stamp.nanosec
  out.string(in.string());  // header.frame_id
  const std::uint32_t height = in.u32(), width = in.u32();
  const std::uint32_t out_h = (height + step - 1) / step, out_w = (width + step - 1) / step;
  out.u32(out_h);
  out.u32(out_w);
  const std::uint32_t nfields = in.u32();
  out.u32(nfields);
  for (std::uint32_t i = 0; i < nfields; ++i) {
    out.string(in.string());
    out.u32(in.u32());  // offset
    out.u8(in.u8());    // datatype
    out.u32(in.u32());  // count
  }
  const bool big = in.boolean();
  const std::uint32_t point_step = in.u32(), row_step = in.u32();
  const std::string_view data = in.bytes();
  const bool dense = in.boolean();
  if (row_step < std::uint64_t{width} * point_step ||
      data.size() < std::uint64_t{row_step} * height)
    throw tools::CdrError("PointCloud2 sample: " + std::to_string(data.size()) +
                          " data bytes for " + std::to_string(width) + " x " +
                          std::to_string(height) + " points of " + std::to_string(point_step) +
                          " bytes (row_step " + std::to_string(row_step) + ")");
  out.boolean(big);
  out.u32(point_step);
  out.u32(out_w * point_step);
  std::uint8_t* dst = out.bytes(std::size_t{out_w} * out_h * point_step);
  for (std::uint32_t r = 0; r < out_h; ++r) {
    const char* row = data.data() + std::size_t{r} * step * row_step;
    for (std::uint32_t c = 0; c < out_w; ++c, dst += point_step)
      std::memcpy(dst, row + std::size_t{c} * step * point_step, point_step);
  }
  out.boolean(dense);
  return std::move(out.finish());
}

}  // namespace sl::view
