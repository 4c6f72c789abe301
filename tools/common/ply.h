// Binary PLY output of point clouds.
#pragma once

#include <cstddef>
#include <string>

#include "sl/pipeline/types.h"

namespace sl::tools {

enum class LengthUnit { kMillimetre, kMetre };

// Writes the finite points of `cloud` as binary little-endian PLY with float
// x, y, z (in `unit`) and intensity, and the organized size, unit and frame as
// header comments. Writes to a temporary file and renames it, so a reader
// never sees a partial file. Returns the number of points written; throws
// std::runtime_error naming the file on I/O failure.
std::size_t writePly(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit);

}  // namespace sl::tools
