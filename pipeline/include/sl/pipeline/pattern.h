// The 3+3 phase-shift pattern of the paper (section 2.2): three sinusoids of
// N_fringe periods across the encoded projector axis, shifted by 2*pi/3, then
// three of one period (the unwrapping cue). Pattern i of a set (i = 0, 1, 2) is
// I_i = A + B cos(phi - 2*pi*i/3) with phi = 2*pi * f * p / L, where p is the
// projector coordinate, L the projector's extent along the axis and f the
// number of periods.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace sl::pipeline {

// Which projector coordinate a pattern encodes. Horizontal fringes vary along
// the projector columns (encode u_p); vertical ones along the rows (v_p).
enum class Direction { kHorizontal, kVertical, kBoth };

const char* toString(Direction d);
// Parses "horizontal" / "vertical" / "both"; throws std::invalid_argument.
Direction directionFromString(const std::string& s);

struct PhaseShift33Pattern {
  std::string name = "3+3";
  Direction direction = Direction::kHorizontal;
  int projector_width = 1824;   // px, addressed resolution
  int projector_height = 1140;  // px
  int fringes = 16;             // N_fringe: periods of the high-frequency set

  // 6 frames per direction: 3 high-frequency, then 3 unit-frequency.
  // kBoth is horizontal then vertical (12 frames).
  int frameCount() const;
  // Wavelength of the high-frequency fringes along an axis of extent L (px).
  double wavelength(int axis_length) const { return double(axis_length) / fringes; }
  // Throws std::invalid_argument naming the bad field.
  void validate() const;
};

// Relative projector intensity in [0, 1] of frame `frame` at projector pixel
// coordinate (u, v): 0.5 + 0.5 cos(phi - shift). Continuous in u, v.
double patternIntensity(const PhaseShift33Pattern& p, int frame, double u, double v);

// The projector images (CV_8UC1, projector_height x projector_width), in
// projection order, rounded to 8 bits as the projector displays them.
std::vector<cv::Mat> generatePatternImages(const PhaseShift33Pattern& p);

}  // namespace sl::pipeline
