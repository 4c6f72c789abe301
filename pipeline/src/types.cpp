#include "sl/pipeline/types.h"

#include <chrono>
#include <cmath>

namespace sl::pipeline {

TimestampNs systemClockNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::size_t PointCloud::validCount() const {
  std::size_t count = 0;
  for (const PointXYZI& p : points) {
    if (std::isfinite(p.z)) ++count;
  }
  return count;
}

}  // namespace sl::pipeline
