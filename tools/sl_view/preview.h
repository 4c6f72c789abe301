// The browser's cloud: an organized PointCloud2 (CDR) decimated by `step` in
// both directions, every field kept, so a 1440 x 1080 cloud (25 MB) becomes
// 360 x 270 (1.6 MB) at step 4. The only message sl_view re-encodes; the
// daemon's own topics are forwarded byte for byte.
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

namespace sl::view {

// Throws sl::tools::CdrError if `cdr` is not a well-formed PointCloud2 whose
// data holds width * height points.
std::vector<std::uint8_t> decimateCloud(std::string_view cdr, int step);

}  // namespace sl::view
