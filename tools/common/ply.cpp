#include "ply.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <sstream>
#include <vector>

namespace sl::tools {

namespace {

// Writes header + binary payload to path + ".part", then renames it.
void writeAtomically(const std::string& path, const std::string& header, const void* data,
                     std::size_t bytes) {
  const std::string temporary = path + ".part";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    if (!out) throw std::runtime_error(temporary + ": cannot open for writing");
    out << header;
    out.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
    if (!out.flush()) throw std::runtime_error(temporary + ": write failed (disk full?)");
  }
  std::error_code error;
  std::filesystem::rename(temporary, path, error);
  if (error) throw std::runtime_error(path + ": cannot rename from .part: " + error.message());
}

const char* unitName(LengthUnit unit) { return unit == LengthUnit::kMetre ? "m" : "mm"; }
float unitScale(LengthUnit unit) { return unit == LengthUnit::kMetre ? 1e-3f : 1.0f; }

}  // namespace

std::size_t writePly(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit) {
  const float scale = unitScale(unit);
  std::vector<float> data;
  data.reserve(cloud.points.size() * 4);
  for (const auto& p : cloud.points) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
    data.insert(data.end(), {p.x * scale, p.y * scale, p.z * scale, p.intensity});
  }
  const std::size_t count = data.size() / 4;
  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\n"
         << "comment generator sl-sensor\n"
         << "comment units " << unitName(unit) << "\n"
         << "comment frame_id " << (cloud.frame_id.empty() ? "unknown" : cloud.frame_id) << "\n"
         << "comment stamp_ns " << cloud.stamp_ns << "\n"
         << "comment organized_width " << cloud.width << "\n"
         << "comment organized_height " << cloud.height << "\n"
         << "element vertex " << count << "\n"
         << "property float x\nproperty float y\nproperty float z\nproperty float intensity\n"
         << "end_header\n";
  writeAtomically(path, header.str(), data.data(), data.size() * sizeof(float));
  return count;
}

std::size_t writePcd(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit) {
  const float scale = unitScale(unit);
  std::vector<float> data;
  data.reserve(cloud.points.size() * 4);
  std::size_t finite = 0;
  for (const auto& p : cloud.points) {
    data.insert(data.end(), {p.x * scale, p.y * scale, p.z * scale, p.intensity});
    finite += std::isfinite(p.z);
  }
  std::ostringstream header;
  header << "# .PCD v0.7 - sl-sensor, units " << unitName(unit) << ", frame "
         << (cloud.frame_id.empty() ? "unknown" : cloud.frame_id) << ", stamp_ns "
         << cloud.stamp_ns << "\n"
         << "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
         << "WIDTH " << cloud.width << "\nHEIGHT " << cloud.height << "\n"
         << "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << cloud.points.size() << "\nDATA binary\n";
  writeAtomically(path, header.str(), data.data(), data.size() * sizeof(float));
  return finite;
}

}  // namespace sl::tools
