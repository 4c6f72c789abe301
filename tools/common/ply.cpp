#include "ply.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <vector>

namespace sl::tools {

std::size_t writePly(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit) {
  const float scale = unit == LengthUnit::kMetre ? 1e-3f : 1.0f;
  std::vector<float> data;
  data.reserve(cloud.points.size() * 4);
  for (const auto& p : cloud.points) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    data.insert(data.end(), {p.x * scale, p.y * scale, p.z * scale, p.intensity});
  }
  const std::size_t count = data.size() / 4;
  const std::string temporary = path + ".part";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    if (!out) throw std::runtime_error(temporary + ": cannot open for writing");
    out << "ply\nformat binary_little_endian 1.0\n"
        << "comment generator sl-sensor\n"
        << "comment units " << (unit == LengthUnit::kMetre ? "m" : "mm") << "\n"
        << "comment frame_id " << (cloud.frame_id.empty() ? "unknown" : cloud.frame_id) << "\n"
        << "comment stamp_ns " << cloud.stamp_ns << "\n"
        << "comment organized_width " << cloud.width << "\n"
        << "comment organized_height " << cloud.height << "\n"
        << "element vertex " << count << "\n"
        << "property float x\nproperty float y\nproperty float z\nproperty float intensity\n"
        << "end_header\n";
    out.write(reinterpret_cast<const char*>(data.data()),
              static_cast<std::streamsize>(data.size() * sizeof(float)));
    if (!out.flush()) throw std::runtime_error(temporary + ": write failed (disk full?)");
  }
  std::error_code error;
  std::filesystem::rename(temporary, path, error);
  if (error) throw std::runtime_error(path + ": cannot rename from .part: " + error.message());
  return count;
}

}  // namespace sl::tools
