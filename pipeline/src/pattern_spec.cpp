#include "sl/pipeline/pattern_spec.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <stdexcept>

#include <opencv2/core.hpp>

#include "frame_layout.h"
#include "sl/pipeline/codec.h"

namespace sl::pipeline {

namespace {

constexpr double kPi = std::numbers::pi;

std::string shortNumber(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", v);
  return text;
}

}  // namespace

const char* toString(PatternFamily f) {
  switch (f) {
    case PatternFamily::kPhaseShift: return "phase_shift";
    case PatternFamily::kTwoPlusOne: return "two_plus_one";
    case PatternFamily::kGrayCode: return "gray_code";
    case PatternFamily::kGrayPhaseShift: return "gray_phase_shift";
    case PatternFamily::kMicroPhaseShift: return "micro_phase_shift";
    case PatternFamily::kModulatedPhaseShift: return "modulated_phase_shift";
  }
  return "?";
}

const char* toString(Unwrapping u) {
  return u == Unwrapping::kHeterodyne ? "heterodyne" : "hierarchical";
}

PatternFamily patternFamilyFromString(const std::string& s) {
  if (s == "phase_shift") return PatternFamily::kPhaseShift;
  if (s == "two_plus_one") return PatternFamily::kTwoPlusOne;
  if (s == "gray_code") return PatternFamily::kGrayCode;
  if (s == "gray_phase_shift") return PatternFamily::kGrayPhaseShift;
  if (s == "micro_phase_shift") return PatternFamily::kMicroPhaseShift;
  if (s == "modulated_phase_shift") return PatternFamily::kModulatedPhaseShift;
  throw std::invalid_argument("unknown pattern family '" + s +
                              "' (supported: phase_shift, phase_shift_3+3, two_plus_one, "
                              "gray_code, gray_phase_shift, micro_phase_shift, "
                              "modulated_phase_shift)");
}

Unwrapping unwrappingFromString(const std::string& s) {
  if (s == "hierarchical" || s == "unit_cue") return Unwrapping::kHierarchical;
  if (s == "heterodyne") return Unwrapping::kHeterodyne;
  throw std::invalid_argument("unknown unwrapping '" + s +
                              "' (supported: unit_cue, hierarchical, heterodyne)");
}

PatternSpec::PatternSpec(const PhaseShift33Pattern& p) : PatternSpec(toSpec(p)) {}

PatternSpec toSpec(const PhaseShift33Pattern& p) {
  PatternSpec s;
  s.name = p.name;
  s.family = PatternFamily::kPhaseShift;
  s.direction = p.direction;
  s.projector_width = p.projector_width;
  s.projector_height = p.projector_height;
  s.steps = 3;
  s.frequencies = {static_cast<double>(p.fringes), 1.0};
  s.unwrapping = Unwrapping::kHierarchical;
  return s;
}

int PatternSpec::fullGrayBits(int axis_length) {
  int bits = 0;
  while ((1 << bits) < axis_length) ++bits;
  return std::max(bits, 1);
}

int PatternSpec::grayBitsUsed(int axis_length) const {
  if (gray_pitch_px > 0) {
    const double stripes = std::ceil(axis_length / gray_pitch_px);
    int bits = 1;
    while (std::ldexp(1.0, bits) < stripes) ++bits;
    return bits;
  }
  return gray_bits > 0 ? gray_bits : fullGrayBits(axis_length);
}

double PatternSpec::stripeWidth(int axis_length) const {
  if (gray_pitch_px > 0) return gray_pitch_px;
  return std::ldexp(1.0, fullGrayBits(axis_length) - grayBitsUsed(axis_length));
}

double PatternSpec::finestPeriod(int axis_length) const {
  switch (family) {
    case PatternFamily::kGrayCode: return 0.0;
    case PatternFamily::kGrayPhaseShift: return stripeWidth(axis_length);
    default: break;
  }
  const double f = frequencies.empty() ? 1.0 : *std::max_element(frequencies.begin(), frequencies.end());
  return axis_length / f;
}

double PatternSpec::microSeparation() const {
  if (family != PatternFamily::kMicroPhaseShift || frequencies.size() < 2) return 0.0;
  double worst = std::numeric_limits<double>::infinity();
  std::vector<int> axes;
  if (direction != Direction::kVertical) axes.push_back(projector_width);
  if (direction != Direction::kHorizontal) axes.push_back(projector_height);
  for (int axis : axes) {
    const double f0 = frequencies[0], wavelength = axis / f0;
    const int candidates = static_cast<int>(std::ceil(f0 - 1e-9));
    for (int pi = 0; pi < 2 * axis; ++pi) {
      const double p = 0.5 * pi;
      const int k_true = static_cast<int>(std::floor(p / wavelength));
      for (int k = 0; k < candidates; ++k) {
        if (k == k_true) continue;
        const double q = p + (k - k_true) * wavelength;
        double d = 0;
        for (std::size_t j = 1; j < frequencies.size(); ++j) {
          const double w = 2.0 * kPi * frequencies[j] / axis;
          const double delta = furtherPhase(j);
          const double e = std::cos(w * p - delta) - std::cos(w * q - delta);
          d += e * e;
        }
        worst = std::min(worst, d);
      }
    }
  }
  return std::isfinite(worst) ? worst : 0.0;
}

int PatternSpec::framesPerDirection() const {
  const int bits_frames = [&] {
    // Bits of the shorter-coded axis do not matter here: both axes of kBoth
    // are validated to have the same count (see validate()).
    const int axis = direction == Direction::kVertical ? projector_height : projector_width;
    const int bits = grayBitsUsed(axis) + (complementary ? 1 : 0);
    return bits * (gray_inverse ? 2 : 1) + (reference_frames ? 2 : 0);
  }();
  switch (family) {
    case PatternFamily::kPhaseShift: return steps * static_cast<int>(frequencies.size());
    case PatternFamily::kTwoPlusOne: return 1 + 2 * static_cast<int>(frequencies.size());
    case PatternFamily::kGrayCode: return bits_frames;
    case PatternFamily::kGrayPhaseShift: return bits_frames + steps;
    case PatternFamily::kMicroPhaseShift: return static_cast<int>(frequencies.size()) + 2;
    case PatternFamily::kModulatedPhaseShift: {
      int frames = 0;
      for (std::size_t j = 0; j < frequencies.size(); ++j)
        frames += (j < modulated_sets.size() && !modulated_sets[j] ? 1 : 3) * steps;
      return frames;
    }
  }
  return 0;
}

int PatternSpec::codeFrameCount() const {
  return framesPerDirection() * (direction == Direction::kBoth ? 2 : 1);
}

int PatternSpec::frameCount() const {
  return frame_order.empty() ? codeFrameCount() : static_cast<int>(frame_order.size());
}

void PatternSpec::validate() const {
  auto fail = [&](const std::string& field, const std::string& what) {
    throw PatternSpecError(field, "pattern '" + name + "': " + field + " " + what);
  };
  if (projector_width <= 0 || projector_height <= 0)
    fail("projector size", "must be positive");
  std::vector<int> axes;
  if (direction != Direction::kVertical) axes.push_back(projector_width);
  if (direction != Direction::kHorizontal) axes.push_back(projector_height);
  const bool sinusoids = family != PatternFamily::kGrayCode;
  const bool gray = family == PatternFamily::kGrayCode || family == PatternFamily::kGrayPhaseShift;
  if (sinusoids) {
    if (shift_sign != 1 && shift_sign != -1) fail("shift_sign", "must be +1 or -1");
    if (!std::isfinite(start_phase_rad)) fail("start_phase", "must be finite");
    if (!(amplitude > 0 && offset - amplitude >= -1e-9 && offset + amplitude <= 1 + 1e-9))
      fail("offset/amplitude", "must satisfy amplitude > 0 and 0 <= offset +- amplitude <= 1");
  }
  const bool modulated = family == PatternFamily::kModulatedPhaseShift;
  if (family == PatternFamily::kPhaseShift || family == PatternFamily::kGrayPhaseShift ||
      modulated) {
    if (steps < 3 || steps > 64) fail("steps", "must be in 3..64");
  }
  if (modulated) {
    if (unwrapping != Unwrapping::kHierarchical)
      fail("unwrapping", "must be hierarchical for modulated_phase_shift");
    const int other = direction == Direction::kVertical ? projector_width : projector_height;
    if (!(carrier_pitch_px >= 3.0 && carrier_pitch_px <= other))
      fail("carrier_pitch", "must be in 3.." + std::to_string(other) + " px");
    if (!modulated_sets.empty()) {
      if (modulated_sets.size() != frequencies.size())
        fail("modulated_sets", "must give one entry per frequency (" +
                                   std::to_string(modulated_sets.size()) + " for " +
                                   std::to_string(frequencies.size()) + " frequencies)");
      if (std::find(modulated_sets.begin(), modulated_sets.end(), true) == modulated_sets.end())
        fail("modulated_sets", "must modulate at least one set (else describe it as phase_shift)");
    }
  } else if (!modulated_sets.empty()) {
    fail("modulated_sets", "is for modulated_phase_shift only");
  }
  if (family == PatternFamily::kMicroPhaseShift) {
    if (!further_phases_rad.empty() && further_phases_rad.size() + 1 != frequencies.size())
      fail("further_phases", "must give one shift per frequency after the first (" +
                                 std::to_string(further_phases_rad.size()) + " for " +
                                 std::to_string(frequencies.size()) + " frequencies)");
    for (double d : further_phases_rad)
      if (!std::isfinite(d)) fail("further_phases", "must be finite");
  } else if (!further_phases_rad.empty()) {
    fail("further_phases", "is for micro_phase_shift only");
  }
  if (family == PatternFamily::kMicroPhaseShift) {
    if (steps != 3) fail("steps", "must be 3 for micro_phase_shift (its first frequency has 3 shifts)");
    if (frequencies.size() < 2 || frequencies.size() > 17)
      fail("frequencies", "must list 2..17 frequencies for micro_phase_shift");
    for (double f : frequencies)
      if (!(f >= 1 && std::isfinite(f))) fail("frequencies", "must be >= 1 period");
    for (int axis : axes)
      if (axis / *std::max_element(frequencies.begin(), frequencies.end()) < 4.0)
        fail("frequencies", "too high for the projector (period must be >= 4 px)");
    // The candidates p + k L / f_0 must differ in the other frequencies'
    // cosines by enough for the modulation a camera records:
    // derivedMinModulation() (5 sigma on the closest wrong candidate) within
    // half of the 8-bit range, as for the phase-shift unwrapping margin.
    const double required = derivedMinModulation(*this, 0.3f);
    const double reachable = 0.5 * 255.0 * amplitude;
    if (required > reachable)
      fail("frequencies", "do not tell the periods of the first frequency apart: the closest "
                          "wrong candidate differs by only " + shortNumber(microSeparation()) +
                          " in the summed squared cosines, which needs a fringe modulation of " +
                          shortNumber(required) + " DN (more than half of the " +
                          shortNumber(2 * reachable) +
                          " DN an 8-bit camera can record); spread the frequencies or add one");
  }
  if (family == PatternFamily::kPhaseShift || family == PatternFamily::kTwoPlusOne || modulated) {
    if (frequencies.empty()) fail("frequencies", "must not be empty");
    for (double f : frequencies)
      if (!(f > 0 && std::isfinite(f))) fail("frequencies", "must be > 0");
    std::vector<double> sorted = frequencies;
    std::sort(sorted.begin(), sorted.end());
    if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end())
      fail("frequencies", "must be distinct");
    const double coarsest = sorted.front(), finest = sorted.back();
    if (unwrapping == Unwrapping::kHierarchical) {
      if (coarsest > 1 + 1e-9)
        fail("frequencies", "need a frequency <= 1 (a unit-frequency cue) for hierarchical unwrapping");
    } else {
      // Beat of beats down to a single phase.
      std::vector<double> level(sorted.rbegin(), sorted.rend());
      while (level.size() > 1) {
        std::vector<double> next;
        for (std::size_t i = 0; i + 1 < level.size(); ++i) next.push_back(level[i] - level[i + 1]);
        level = next;
      }
      if (frequencies.size() < 2 || !(level[0] > 0 && level[0] <= 1 + 1e-9))
        fail("frequencies", "must beat down to one period (e.g. 70, 64, 59: (70-64)-(64-59) = 1) for heterodyne unwrapping");
    }
    for (int axis : axes) {
      if (axis / finest < 4.0)
        fail("frequencies", "too high for the projector (" + std::to_string(finest) +
                                " periods over " + std::to_string(axis) + " px; period must be >= 4 px)");
    }
  }
  if (gray) {
    for (int axis : axes) {
      const int full = fullGrayBits(axis);
      const int extra = complementary ? 1 : 0;
      if (gray_pitch_px != 0) {
        if (gray_bits != 0) fail("bits", "give one of bits and the stripe pitch");
        if (!(std::isfinite(gray_pitch_px) && gray_pitch_px >= 2.0 && gray_pitch_px <= axis))
          fail("pitch_px", "stripe pitch " + std::to_string(gray_pitch_px) +
                               " px must be in 2.." + std::to_string(axis) + " px");
      } else if (gray_bits < 0 || gray_bits + extra > full) {
        fail("bits", "must be in 0.." + std::to_string(full - extra) + " for " +
                         std::to_string(axis) + " px (0 = all)");
      }
      // Gray + phase shift may threshold against the sinusoids' mean.
      if (!reference_frames && !gray_inverse && family == PatternFamily::kGrayCode)
        fail("reference_frames", "or inverse patterns are needed to threshold the bits of a "
                                 "Gray code without phase shift");
    }
    if (axes.size() == 2 &&
        grayBitsUsed(projector_width) != grayBitsUsed(projector_height))
      fail("bits", "must give the same bit count on both axes (set bits explicitly)");
    if (family == PatternFamily::kGrayPhaseShift) {
      for (int axis : axes)
        if (stripeWidth(axis) < 4.0)
          fail(gray_pitch_px > 0 ? "pitch_px" : "bits", "leave a phase period of " + std::to_string(stripeWidth(axis)) +
                           " px; need >= 4 px");
    }
  }
  if (family == PatternFamily::kPhaseShift || family == PatternFamily::kTwoPlusOne || modulated) {
    // Unwrapping margin: the modulation the noisiest frequency step needs for
    // its fringe orders to be picked with a 5-sigma margin (codec.h) must be
    // within reach of the camera.
    const double required = derivedMinModulation(*this, 0.3f);
    const double reachable = 0.5 * 255.0 * amplitude;
    if (required > reachable) {
      std::vector<double> f = frequencies;
      std::sort(f.begin(), f.end(), std::greater<>());
      std::string ratios;
      for (std::size_t i = 0; unwrapping == Unwrapping::kHierarchical && i + 1 < f.size(); ++i)
        ratios += (ratios.empty() ? "" : ", ") + std::to_string(f[i] / f[i + 1]);
      fail("frequencies",
           "cannot be unwrapped reliably: the frequency steps (ratios " +
               (ratios.empty() ? std::string("of the beats") : ratios) +
               ") need a fringe modulation of " + std::to_string(required) +
               " DN for 5-sigma fringe orders, more than half of the " +
               std::to_string(2 * reachable) +
               " DN an 8-bit camera can record; add intermediate frequencies (ratio <= ~40 per "
               "step)");
    }
  }
  if (!frame_order.empty()) {
    const int n = codeFrameCount();
    std::vector<int> seen(n, 0);
    for (int c : frame_order) {
      if (c == kSkippedFrame) continue;
      if (c < 0 || c >= n)
        fail("frame_order", "entry " + std::to_string(c) + " is outside 0.." +
                                std::to_string(n - 1) + " (-1 = skipped frame)");
      if (++seen[c] > 1)
        fail("frame_order", "lists canonical frame " + std::to_string(c) + " twice");
    }
    for (int c = 0; c < n; ++c)
      if (seen[c] == 0)
        fail("frame_order", "misses canonical frame " + std::to_string(c) + " (the code has " +
                                std::to_string(n) + " frames; each must be captured once)");
  }
}

namespace detail {

std::vector<FrameInfo> canonicalFrames(const PatternSpec& s) {
  using Kind = FrameInfo::Kind;
  std::vector<FrameInfo> frames;
  auto direction = [&](bool columns) {
    const int axis = s.axisLength(columns);
    auto sinusoid = [&](double frequency, double origin, double delta) {
      FrameInfo f;
      f.kind = Kind::kSinusoid;
      f.columns = columns;
      f.frequency = frequency;
      f.origin = origin;
      f.delta = delta;
      frames.push_back(f);
    };
    auto simple = [&](Kind kind) {
      FrameInfo f;
      f.kind = kind;
      f.columns = columns;
      frames.push_back(f);
    };
    auto gray = [&] {
      if (s.reference_frames) {
        simple(Kind::kWhite);
        simple(Kind::kBlack);
      }
      const int extra = s.family == PatternFamily::kGrayPhaseShift && s.complementary ? 1 : 0;
      const int bits = s.grayBitsUsed(axis) + extra;
      // The complementary bit codes half stripes.
      const double stripe = s.stripeWidth(axis) / (extra ? 2.0 : 1.0);
      for (int b = 0; b < bits; ++b) {
        for (int inv = 0; inv < (s.gray_inverse ? 2 : 1); ++inv) {
          FrameInfo f;
          f.kind = Kind::kGrayBit;
          f.columns = columns;
          f.bit = b;
          f.code_bits = bits;
          f.stripe = stripe;
          f.inverted = inv == 1;
          frames.push_back(f);
        }
      }
    };
    const double sign = s.shift_sign;
    switch (s.family) {
      case PatternFamily::kPhaseShift:
        for (double fr : s.frequencies)
          for (int n = 0; n < s.steps; ++n)
            sinusoid(fr, 0.0, s.start_phase_rad + sign * 2.0 * kPi * n / s.steps);
        break;
      case PatternFamily::kTwoPlusOne:
        for (std::size_t i = 0; i < s.frequencies.size(); ++i) {
          sinusoid(s.frequencies[i], 0.0, s.start_phase_rad);
          if (i == 0) simple(Kind::kFlat);
          sinusoid(s.frequencies[i], 0.0, s.start_phase_rad + sign * 0.5 * kPi);
        }
        break;
      case PatternFamily::kGrayCode:
        gray();
        break;
      case PatternFamily::kMicroPhaseShift:
        for (int n = 0; n < 3; ++n)
          sinusoid(s.frequencies[0], 0.0, s.start_phase_rad + sign * 2.0 * kPi * n / 3);
        for (std::size_t j = 1; j < s.frequencies.size(); ++j)
          sinusoid(s.frequencies[j], 0.0, s.furtherPhase(j));
        break;
      case PatternFamily::kModulatedPhaseShift:
        for (std::size_t j = 0; j < s.frequencies.size(); ++j)
          for (int n = 0; n < s.steps; ++n)
            for (int m = 0; m < (s.setModulated(j) ? 3 : 1); ++m) {
              sinusoid(s.frequencies[j], 0.0, s.start_phase_rad + sign * 2.0 * kPi * n / s.steps);
              if (!s.setModulated(j)) continue;
              frames.back().carrier_pitch = s.carrier_pitch_px;
              frames.back().carrier_shift = 2.0 * kPi * m / 3;
            }
        break;
      case PatternFamily::kGrayPhaseShift: {
        gray();
        // One period per stripe, phase 0 at the stripe boundary p = -0.5.
        const double period = s.stripeWidth(axis);
        for (int n = 0; n < s.steps; ++n)
          sinusoid(axis / period, -0.5, s.start_phase_rad + sign * 2.0 * kPi * n / s.steps);
        break;
      }
    }
  };
  if (s.direction != Direction::kVertical) direction(true);
  if (s.direction != Direction::kHorizontal) direction(false);
  return frames;
}

double frameIntensity(const PatternSpec& s, const FrameInfo& f, double u, double v) {
  const double p = f.columns ? u : v;
  const double axis = s.axisLength(f.columns);
  switch (f.kind) {
    case FrameInfo::Kind::kSinusoid: {
      const double value =
          s.offset + s.amplitude * std::cos(2.0 * kPi * f.frequency * (p - f.origin) / axis - f.delta);
      if (f.carrier_pitch <= 0) return value;
      const double q = f.columns ? v : u;
      return value * (0.5 + 0.5 * std::cos(2.0 * kPi * q / f.carrier_pitch - f.carrier_shift));
    }
    case FrameInfo::Kind::kFlat: return s.offset;
    case FrameInfo::Kind::kWhite: return 1.0;
    case FrameInfo::Kind::kBlack: return 0.0;
    case FrameInfo::Kind::kGrayBit: {
      const long stripe = static_cast<long>(std::floor((p + 0.5) / f.stripe));
      const long code = stripe ^ (stripe >> 1);
      const long bit = (code >> (f.code_bits - 1 - f.bit)) & 1;
      return static_cast<double>(f.inverted ? 1 - bit : bit);
    }
  }
  return 0.0;
}

}  // namespace detail

double patternIntensity(const PatternSpec& spec, int frame, double u, double v) {
  const auto frames = detail::canonicalFrames(spec);
  if (frame < 0 || frame >= spec.frameCount())
    throw std::out_of_range("pattern '" + spec.name + "': frame " + std::to_string(frame) +
                            " out of range");
  const int canonical = spec.frame_order.empty() ? frame : spec.frame_order[frame];
  if (canonical == kSkippedFrame) return 0.0;
  return detail::frameIntensity(spec, frames[canonical], u, v);
}

std::vector<cv::Mat> generatePatternImages(const PatternSpec& spec) {
  spec.validate();
  const auto frames = detail::canonicalFrames(spec);
  std::vector<cv::Mat> canonical;
  for (const detail::FrameInfo& f : frames) {
    if (f.carrier_pitch > 0) {
      // Two-dimensional: the sinusoid along one axis times the carrier.
      cv::Mat image(spec.projector_height, spec.projector_width, CV_8UC1);
      for (int r = 0; r < spec.projector_height; ++r)
        for (int c = 0; c < spec.projector_width; ++c)
          image.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(std::lround(
              255.0 * std::clamp(detail::frameIntensity(spec, f, c, r), 0.0, 1.0)));
      canonical.push_back(image);
      continue;
    }
    const int extent = spec.axisLength(f.columns);
    std::vector<std::uint8_t> profile(extent);
    for (int i = 0; i < extent; ++i) {
      const double value = detail::frameIntensity(spec, f, i, i);
      profile[i] = static_cast<std::uint8_t>(std::lround(255.0 * std::clamp(value, 0.0, 1.0)));
    }
    cv::Mat image(spec.projector_height, spec.projector_width, CV_8UC1);
    for (int r = 0; r < spec.projector_height; ++r) {
      auto* row = image.ptr<std::uint8_t>(r);
      if (f.columns) {
        std::copy(profile.begin(), profile.end(), row);
      } else {
        std::fill(row, row + spec.projector_width, profile[r]);
      }
    }
    canonical.push_back(image);
  }
  if (spec.frame_order.empty()) return canonical;
  std::vector<cv::Mat> ordered;
  for (int c : spec.frame_order)
    ordered.push_back(c == kSkippedFrame
                          ? cv::Mat(spec.projector_height, spec.projector_width, CV_8UC1,
                                    cv::Scalar(0))
                          : canonical[c]);
  return ordered;
}

}  // namespace sl::pipeline
