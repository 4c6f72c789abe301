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

std::size_t writePlyWithQuality(const pipeline::PointCloud& cloud, const cv::Mat& depth_sigma,
                                const cv::Mat& normals, const std::string& path, LengthUnit unit) {
  const cv::Size size(cloud.width, cloud.height);
  if (!depth_sigma.empty() && (depth_sigma.type() != CV_32FC1 || depth_sigma.size() != size))
    throw std::invalid_argument(path + ": depth sigma must be CV_32FC1 of the cloud's size");
  if (!normals.empty() && (normals.type() != CV_32FC3 || normals.size() != size))
    throw std::invalid_argument(path + ": normals must be CV_32FC3 of the cloud's size");
  if (static_cast<int>(cloud.points.size()) != cloud.width * cloud.height)
    throw std::invalid_argument(path + ": the cloud is not organized");
  const float scale = unitScale(unit);
  const int fields = 4 + (depth_sigma.empty() ? 0 : 1) + (normals.empty() ? 0 : 3);
  std::vector<float> data;
  data.reserve(cloud.points.size() * fields);
  for (int v = 0; v < cloud.height; ++v)
    for (int u = 0; u < cloud.width; ++u) {
      const auto& p = cloud.points[static_cast<std::size_t>(v) * cloud.width + u];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) continue;
      data.insert(data.end(), {p.x * scale, p.y * scale, p.z * scale, p.intensity});
      if (!normals.empty()) {
        const cv::Vec3f n = normals.at<cv::Vec3f>(v, u);
        data.insert(data.end(), {n[0], n[1], n[2]});
      }
      if (!depth_sigma.empty()) data.push_back(depth_sigma.at<float>(v, u) * scale);
    }
  const std::size_t count = data.size() / fields;
  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\n"
         << "comment generator sl-sensor\n"
         << "comment units " << unitName(unit) << "\n"
         << "comment frame_id " << (cloud.frame_id.empty() ? "unknown" : cloud.frame_id) << "\n"
         << "comment stamp_ns " << cloud.stamp_ns << "\n"
         << "comment organized_width " << cloud.width << "\n"
         << "comment organized_height " << cloud.height << "\n";
  if (!depth_sigma.empty())
    header << "comment confidence: expected depth standard deviation (" << unitName(unit)
           << "), NaN unknown\n";
  header << "element vertex " << count << "\n"
         << "property float x\nproperty float y\nproperty float z\nproperty float intensity\n";
  if (!normals.empty()) header << "property float nx\nproperty float ny\nproperty float nz\n";
  if (!depth_sigma.empty()) header << "property float confidence\n";
  header << "end_header\n";
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
