#include "sl/daemon/cloud_layout.h"

#include <cmath>

namespace sl::daemon {

// The size packCloud's organized (decimated) layout gives.
std::size_t maxPackedBytes(int width, int height, const CloudLayout& layout) {
  const int step = layout.decimation;
  return static_cast<std::size_t>((width + step - 1) / step) *
         static_cast<std::size_t>((height + step - 1) / step) * sizeof(pipeline::PointXYZI);
}

bool packsInPlace(const CloudLayout& layout, double unit_m) {
  return unit_m == 1.0 && layout.decimation == 1 && !layout.valid_only;
}

PackedCloud packCloud(const pipeline::PointCloud& cloud, double unit_m, const CloudLayout& layout,
                      std::vector<float>& buffer) {
  static_assert(sizeof(pipeline::PointXYZI) == 16, "x, y, z, intensity: the PointCloud2 layout");
  const int step = layout.decimation;
  PackedCloud packed;
  if (packsInPlace(layout, unit_m)) {
    packed.data = reinterpret_cast<const std::uint8_t*>(cloud.points.data());
    packed.bytes = cloud.points.size() * sizeof(pipeline::PointXYZI);
    packed.width = static_cast<std::uint32_t>(cloud.width);
    packed.height = static_cast<std::uint32_t>(cloud.height);
    return packed;  // organized: may hold NaN points, dense = false
  }
  const float scale = static_cast<float>(unit_m);
  const int out_width = (cloud.width + step - 1) / step;
  const int out_height = (cloud.height + step - 1) / step;
  buffer.resize(4 * static_cast<std::size_t>(out_width) * out_height);
  float* out = buffer.data();
  for (int v = 0; v < cloud.height; v += step) {
    const pipeline::PointXYZI* row = cloud.points.data() + static_cast<std::size_t>(v) * cloud.width;
    for (int u = 0; u < cloud.width; u += step) {
      const pipeline::PointXYZI& p = row[u];
      if (layout.valid_only && std::isnan(p.z)) continue;
      out[0] = p.x * scale;
      out[1] = p.y * scale;
      out[2] = p.z * scale;
      out[3] = p.intensity;
      out += 4;
    }
  }
  const std::size_t points = static_cast<std::size_t>(out - buffer.data()) / 4;
  packed.data = reinterpret_cast<const std::uint8_t*>(buffer.data());
  packed.bytes = points * sizeof(pipeline::PointXYZI);
  if (layout.valid_only) {
    packed.width = static_cast<std::uint32_t>(points);
    packed.height = 1;
    packed.dense = true;
  } else {
    packed.width = static_cast<std::uint32_t>(out_width);
    packed.height = static_cast<std::uint32_t>(out_height);
  }
  return packed;
}

}  // namespace sl::daemon
