#include "sl/dds/cloud_layout.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace sl::dds {

int floatsPerPoint(const CloudLayout& layout) {
  return 4 + (layout.normals ? 3 : 0) + (layout.confidence ? 1 : 0);
}

// The size packCloud's organized (decimated) layout gives.
std::size_t maxPackedBytes(int width, int height, const CloudLayout& layout) {
  const int step = layout.decimation;
  return static_cast<std::size_t>((width + step - 1) / step) *
         static_cast<std::size_t>((height + step - 1) / step) * floatsPerPoint(layout) * sizeof(float);
}

bool packsInPlace(const CloudLayout& layout, double unit_m) {
  return unit_m == 1.0 && layout.decimation == 1 && !layout.valid_only && !layout.normals &&
         !layout.confidence;
}

namespace {

// `m` of `type` and the cloud's size, or an error naming `what`.
void checkQualityMap(const cv::Mat& m, int type, const pipeline::PointCloud& cloud, const char* what) {
  if (m.empty())
    throw std::invalid_argument(std::string("cloud layout asks for ") + what + " but none was computed");
  if (m.type() != type || m.cols != cloud.width || m.rows != cloud.height)
    throw std::invalid_argument(std::string(what) + " map: " + std::to_string(m.cols) + " x " +
                                std::to_string(m.rows) + " of type " + std::to_string(m.type()) +
                                ", the cloud is " + std::to_string(cloud.width) + " x " +
                                std::to_string(cloud.height));
}

}  // namespace

PackedCloud packCloud(const pipeline::PointCloud& cloud, double unit_m, const CloudLayout& layout,
                      std::vector<float>& buffer, const PointQuality* quality) {
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
  static const PointQuality kNone;
  const PointQuality& q = quality ? *quality : kNone;
  if (layout.normals) checkQualityMap(q.normals, CV_32FC3, cloud, "normals");
  if (layout.confidence) checkQualityMap(q.depth_sigma, CV_32FC1, cloud, "confidence (depth sigma)");
  const int floats = floatsPerPoint(layout);
  const float scale = static_cast<float>(unit_m);
  const int out_width = (cloud.width + step - 1) / step;
  const int out_height = (cloud.height + step - 1) / step;
  buffer.resize(static_cast<std::size_t>(floats) * out_width * out_height);
  float* out = buffer.data();
  for (int v = 0; v < cloud.height; v += step) {
    const pipeline::PointXYZI* row = cloud.points.data() + static_cast<std::size_t>(v) * cloud.width;
    const cv::Vec3f* normals = layout.normals ? q.normals.ptr<cv::Vec3f>(v) : nullptr;
    const float* sigma = layout.confidence ? q.depth_sigma.ptr<float>(v) : nullptr;
    for (int u = 0; u < cloud.width; u += step) {
      const pipeline::PointXYZI& p = row[u];
      if (layout.valid_only && std::isnan(p.z)) continue;
      out[0] = p.x * scale;
      out[1] = p.y * scale;
      out[2] = p.z * scale;
      out[3] = p.intensity;
      float* f = out + 4;
      if (normals) {
        f[0] = normals[u][0];
        f[1] = normals[u][1];
        f[2] = normals[u][2];
        f += 3;
      }
      if (sigma) *f = sigma[u] * scale;
      out += floats;
    }
  }
  const std::size_t points = static_cast<std::size_t>(out - buffer.data()) / floats;
  packed.data = reinterpret_cast<const std::uint8_t*>(buffer.data());
  packed.point_step = static_cast<std::uint32_t>(floats * sizeof(float));
  packed.bytes = points * packed.point_step;
  packed.normals = layout.normals;
  packed.confidence = layout.confidence;
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

}  // namespace sl::dds
