// Point cloud files: binary PLY (finite points) and binary PCD (organized,
// NaN kept), both written atomically (temporary file + rename).
#pragma once

#include <cstddef>
#include <string>

#include "sl/pipeline/types.h"

namespace sl::tools {

enum class LengthUnit { kMillimetre, kMetre };

// Writes the finite points of `cloud` as binary little-endian PLY with float
// x, y, z (in `unit`) and intensity, and the organized size, unit and frame as
// header comments. Returns the number of points written; throws
// std::runtime_error naming the file on I/O failure.
std::size_t writePly(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit);

// Writes `cloud` as binary PCD v0.7 (the Point Cloud Library's format),
// organized: WIDTH x HEIGHT as the camera, fields x y z intensity (float),
// invalid points as NaN, x y z in `unit`. Returns the number of finite points.
std::size_t writePcd(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit);

}  // namespace sl::tools
