// What rt/<ns>/points carries of a scan: the full organized cloud (the
// default), every N-th pixel of every N-th row (dds.points_decimation), or
// the valid points only (dds.points_valid_only, an unorganized cloud of
// height 1). Lighter clouds for links or subscribers that cannot take
// 25 MB at the scan rate (README "Topics"). Optionally with per-point
// quality fields (dds.points_normals, dds.points_confidence;
// docs/metrology.md "Per-point quality").
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/types.h"

namespace sl::dds {

struct CloudLayout {
  int decimation = 1;       // 1..16: keep pixels (u, v) with u % N == 0 and v % N == 0
  bool valid_only = false;  // drop NaN points (organized -> height 1)
  bool normals = false;     // + normal_x, normal_y, normal_z (unit, towards the camera)
  bool confidence = false;  // + confidence: the expected depth sigma, metres
};

// float32 values a point: x, y, z, intensity [normal_x normal_y normal_z]
// [confidence], in this order.
int floatsPerPoint(const CloudLayout& layout);

// Per-point quality of one organized cloud (pipeline/point_quality.h), the
// cloud's size; a Mat is empty when not computed.
struct PointQuality {
  cv::Mat depth_sigma;  // CV_32FC1, the cloud's length unit, NaN where unknown
  cv::Mat normals;      // CV_32FC3, unit, NaN where unknown
};

// PointCloud2 data of x, y, z (metres) and intensity, float32 each, 16 bytes a
// point, then the layout's optional fields (floatsPerPoint).
struct PackedCloud {
  const std::uint8_t* data = nullptr;  // the cloud's own points or `buffer`
  std::size_t bytes = 0;
  std::uint32_t width = 0, height = 0;
  bool dense = false;  // true only when it is known that no point is NaN (valid_only)
  bool normals = false, confidence = false;  // the optional fields present
  std::uint32_t point_step = 16;             // bytes a point
};

// Bytes of the packed data of a width x height cloud at most (valid_only
// drops NaN points, so it may be fewer).
std::size_t maxPackedBytes(int width, int height, const CloudLayout& layout);

// True when packCloud's data is the cloud's own points (the full organized
// layout, in metres, no optional field): no copy, and `buffer` is not used.
bool packsInPlace(const CloudLayout& layout, double unit_m);

// Packs `cloud` (x, y, z in units of `unit_m` metres) as `layout` says: in
// place (packsInPlace) or written to `buffer` in one pass. The result points
// into `cloud` or `buffer`, so both must outlive it. The optional fields come
// from `quality` (depth sigma scaled by `unit_m` to metres); throws
// std::invalid_argument when the layout asks for one that `quality` lacks or
// whose size differs from the cloud's.
PackedCloud packCloud(const pipeline::PointCloud& cloud, double unit_m, const CloudLayout& layout,
                      std::vector<float>& buffer, const PointQuality* quality = nullptr);

}  // namespace sl::dds
