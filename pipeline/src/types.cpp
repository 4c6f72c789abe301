#include "sl/pipeline/types.h"

#include <cmath>

namespace sl::pipeline {

std::size_t PointCloud::validCount() const {
  std::size_t count = 0;
  for (const PointXYZI& p : points) {
    if (std::isfinite(p.z)) ++count;
  }
  return count;
}

}  // namespace sl::pipeline
