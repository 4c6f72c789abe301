#include "sl/pipeline/pattern.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include <opencv2/core.hpp>

namespace sl::pipeline {

const char* toString(Direction d) {
  switch (d) {
    case Direction::kHorizontal: return "horizontal";
    case Direction::kVertical: return "vertical";
    case Direction::kBoth: return "both";
  }
  return "?";
}

Direction directionFromString(const std::string& s) {
  if (s == "horizontal") return Direction::kHorizontal;
  if (s == "vertical") return Direction::kVertical;
  if (s == "both") return Direction::kBoth;
  throw std::invalid_argument("direction must be horizontal, vertical or both, not '" + s + "'");
}

int PhaseShift33Pattern::frameCount() const { return direction == Direction::kBoth ? 12 : 6; }

void PhaseShift33Pattern::validate() const {
  if (projector_width <= 0 || projector_height <= 0)
    throw std::invalid_argument("pattern '" + name + "': projector size must be positive");
  if (fringes < 1)
    throw std::invalid_argument("pattern '" + name + "': fringes must be >= 1");
  // The shortest encoded axis bounds the fringe count (both axes for kBoth).
  const int extent = direction == Direction::kVertical     ? projector_height
                     : direction == Direction::kHorizontal ? projector_width
                                                           : std::min(projector_width, projector_height);
  if (fringes * 4 > extent)
    throw std::invalid_argument("pattern '" + name + "': fringes too many for the projector (" +
                                std::to_string(fringes) + " periods over " +
                                std::to_string(extent) + " px)");
}

namespace {

struct FrameEncoding {
  bool columns;   // encodes u_p (true) or v_p (false)
  int periods;    // periods across the axis
  int step;       // 0, 1, 2: phase shift 2*pi*step/3
};

FrameEncoding encodingOf(const PhaseShift33Pattern& p, int frame) {
  if (frame < 0 || frame >= p.frameCount())
    throw std::out_of_range("pattern '" + p.name + "': frame " + std::to_string(frame) +
                            " out of range");
  const bool columns = p.direction == Direction::kHorizontal ||
                       (p.direction == Direction::kBoth && frame < 6);
  const int in_set = frame % 6;
  return {columns, in_set < 3 ? p.fringes : 1, in_set % 3};
}

}  // namespace

double patternIntensity(const PhaseShift33Pattern& p, int frame, double u, double v) {
  const FrameEncoding e = encodingOf(p, frame);
  const double coord = e.columns ? u : v;
  const double extent = e.columns ? p.projector_width : p.projector_height;
  const double phi = 2.0 * std::numbers::pi * e.periods * coord / extent;
  return 0.5 + 0.5 * std::cos(phi - 2.0 * std::numbers::pi * e.step / 3.0);
}

std::vector<cv::Mat> generatePatternImages(const PhaseShift33Pattern& p) {
  p.validate();
  std::vector<cv::Mat> images;
  for (int f = 0; f < p.frameCount(); ++f) {
    const FrameEncoding e = encodingOf(p, f);
    const int extent = e.columns ? p.projector_width : p.projector_height;
    std::vector<std::uint8_t> profile(extent);
    for (int i = 0; i < extent; ++i) {
      const double value = e.columns ? patternIntensity(p, f, i, 0) : patternIntensity(p, f, 0, i);
      profile[i] = static_cast<std::uint8_t>(std::lround(255.0 * value));
    }
    cv::Mat image(p.projector_height, p.projector_width, CV_8UC1);
    for (int r = 0; r < p.projector_height; ++r) {
      auto* row = image.ptr<std::uint8_t>(r);
      for (int c = 0; c < p.projector_width; ++c) row[c] = e.columns ? profile[c] : profile[r];
    }
    images.push_back(image);
  }
  return images;
}

}  // namespace sl::pipeline
