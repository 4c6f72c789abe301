#include "preview.h"

#include <cstring>
#include <string>

#include "common/cdr.h"
#include "common/point_cloud2_cdr.h"

namespace sl::view {

std::vector<std::uint8_t> decimateCloud(std::string_view cdr, int step) {
  if (step < 1) throw tools::CdrError("decimation step must be >= 1");
  const tools::PointCloud2View in = tools::parsePointCloud2(
      reinterpret_cast<const std::uint8_t*>(cdr.data()), cdr.size());
  tools::CdrWriter out;
  out.i32(in.stamp_sec);
  out.u32(in.stamp_nanosec);
  out.string(in.frame_id);
  const std::uint32_t height = in.height, width = in.width;
  const std::uint32_t out_h = (height + step - 1) / step, out_w = (width + step - 1) / step;
  out.u32(out_h);
  out.u32(out_w);
  out.u32(static_cast<std::uint32_t>(in.fields.size()));
  for (const tools::PointFieldCdr& f : in.fields) {
    out.string(f.name);
    out.u32(f.offset);
    out.u8(f.datatype);
    out.u32(f.count);
  }
  const std::uint32_t point_step = in.point_step, row_step = in.row_step;
  const std::string_view data = in.data;
  out.boolean(in.is_bigendian);
  out.u32(point_step);
  out.u32(out_w * point_step);
  std::uint8_t* dst = out.bytes(std::size_t{out_w} * out_h * point_step);
  for (std::uint32_t r = 0; r < out_h; ++r) {
    const char* row = data.data() + std::size_t{r} * step * row_step;
    for (std::uint32_t c = 0; c < out_w; ++c, dst += point_step)
      std::memcpy(dst, row + std::size_t{c} * step * point_step, point_step);
  }
  out.boolean(in.is_dense);
  return std::move(out.finish());
}

}  // namespace sl::view
