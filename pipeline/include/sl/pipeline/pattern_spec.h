// A structured-light pattern described as data: family, parameters, encoded
// direction, projector resolution and frame order. Codecs (codec.h) generate
// the projector images of a PatternSpec and decode camera images of it.
//
// Conventions shared by all families:
// - Projector coordinates are in projector px of the addressed resolution
//   (1824 x 1140 for the LightCrafter 4500), origin at the centre of the
//   top-left pixel: projector column c covers [c - 0.5, c + 0.5).
// - Horizontal patterns encode the projector column u_p (the stripes are
//   vertical lines), vertical patterns the row v_p; `both` is the horizontal
//   block of frames followed by the vertical block.
// - Relative projector intensity is in [0, 1] (0 = black, 1 = full white);
//   8-bit images hold round(255 * intensity).
// - A sinusoid of `f` periods across an axis of L px, shift delta:
//   I(p) = offset + amplitude * cos(2*pi*f*p/L - delta). Frame n of an N-step
//   set has delta_n = start_phase + shift_sign * 2*pi*n/N.
#pragma once

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "sl/pipeline/pattern.h"

namespace sl::pipeline {

// frame_order entry of a captured frame that is not part of the code.
inline constexpr int kSkippedFrame = -1;

// Thrown by PatternSpec::validate(): `field` names the PatternSpec field at
// fault (projector size, steps, frequencies, shift_sign, start_phase,
// offset/amplitude, bits, reference_frames, frame_order) so that readers can
// blame their own key.
struct PatternSpecError : std::invalid_argument {
  PatternSpecError(std::string field_name, const std::string& message)
      : std::invalid_argument(message), field(std::move(field_name)) {}
  std::string field;
};

enum class PatternFamily {
  // N-step phase shift (N >= 3) at one or more frequencies, temporal unwrapping.
  kPhaseShift,
  // 2+1 (sl_sensor's two_plus_one_with_tpu): per direction a quadrature pair
  // at the first frequency with a flat frame between them, then a quadrature
  // pair per further frequency (the unit-frequency cue):
  // [f0 delta0, flat, f0 delta1, f1 delta0, f1 delta1, ...], delta1 = delta0
  // + shift_sign * pi/2; the flat frame is `offset` (A).
  kTwoPlusOne,
  // Reflected binary Gray code of the projector coordinate, MSB first.
  kGrayCode,
  // Gray code for the fringe order + N-step phase shift with one period per
  // Gray stripe (optionally complementary: one more Gray bit of half the
  // stripe width against edge errors). Bits are thresholded against the
  // reference frames, the inverse frames, or (with neither) the mean A of
  // the phase-shift frames.
  kGrayPhaseShift,
  // Micro phase shifting (Gupta and Nayar 2012): F >= 2 high frequencies in a
  // narrow band; per direction F + 2 frames: the first listed frequency at
  // the three shifts delta_0, delta_1, delta_2 (steps is 3), then each
  // further frequency once at delta_0, or at its own shift
  // (further_phases_rad; SLStudio puts every other one at pi). No unit cue:
  // the coordinate is the candidate period of the first frequency whose
  // cosines match the others'.
  kMicroPhaseShift,
  // Modulated phase shifting (Chen, Stewart, Yang 2008): the N-step sets of
  // kPhaseShift (hierarchical unwrapping) with every frame multiplied by a
  // carrier 0.5 + 0.5 cos(2 pi q / carrier_pitch_px - 2 pi m / 3) along the
  // other projector axis q, at m = 0, 1, 2: per direction, for each
  // frequency, for each step, the three carrier shifts (3 N F frames). The
  // carrier separates direct light from interreflections and scattering.
  // A set marked unmodulated (modulated_sets) is projected as phase_shift's
  // N frames without carrier (SLStudio's unit-frequency cue).
  kModulatedPhaseShift,
};

enum class Unwrapping {
  // Each frequency is unwrapped with the next lower one (sorted by
  // frequency); the lowest must be <= 1 period across the axis. A unit
  // frequency cue (3+3) is the two-frequency case.
  kHierarchical,
  // Multi-wavelength heterodyne: beats of neighbouring frequencies (sorted
  // descending), beats of the beats..., down to one beat of <= 1 period,
  // then unwrapped back up to the highest frequency.
  kHeterodyne,
};

const char* toString(PatternFamily f);
const char* toString(Unwrapping u);
// Parse the names used in YAML ("phase_shift", "two_plus_one", "gray_code",
// "gray_phase_shift", "micro_phase_shift", "modulated_phase_shift";
// "hierarchical", "unit_cue", "heterodyne"). Throw
// std::invalid_argument listing the valid names.
PatternFamily patternFamilyFromString(const std::string& s);
Unwrapping unwrappingFromString(const std::string& s);

struct PatternSpec {
  PatternSpec() = default;
  // Implicit on purpose: the legacy 3+3 description converts to its spec, so
  // code written for PhaseShift33Pattern keeps working (see toSpec()).
  PatternSpec(const PhaseShift33Pattern& p);  // NOLINT(google-explicit-constructor)

  std::string name = "pattern";
  PatternFamily family = PatternFamily::kPhaseShift;
  Direction direction = Direction::kHorizontal;
  int projector_width = 1824;   // px, addressed resolution
  int projector_height = 1140;  // px

  // --- sinusoids (kPhaseShift, kTwoPlusOne, kGrayPhaseShift) ---
  int steps = 3;  // N (kPhaseShift, kGrayPhaseShift); kTwoPlusOne always 2
  // Periods across the encoded axis, in projection order (kPhaseShift,
  // kTwoPlusOne). Need not be integers; the coordinate is periodic with the
  // axis length when the coarsest frequency is 1.
  std::vector<double> frequencies{16.0, 1.0};
  Unwrapping unwrapping = Unwrapping::kHierarchical;
  int shift_sign = 1;            // +1 or -1
  double start_phase_rad = 0.0;  // delta_0
  double offset = 0.5;           // mean relative intensity
  double amplitude = 0.5;        // offset +- amplitude must stay in [0, 1]
  double carrier_pitch_px = 8.0; // kModulatedPhaseShift: carrier period along the other axis
  // kModulatedPhaseShift: per frequency (listed order) whether its set is
  // multiplied by the carrier (3 frames per step) or projected without it
  // (1 frame per step). Empty = every set modulated; else one entry per
  // frequency, at least one true.
  std::vector<bool> modulated_sets;
  // kMicroPhaseShift: the shift delta (rad) of the frame of each further
  // frequency (frequencies[1..]), in place of delta_0: I = offset + amplitude
  // cos(2 pi f_j p / L - further_phases_rad[j - 1]). Empty = all at delta_0.
  std::vector<double> further_phases_rad;

  // --- Gray code (kGrayCode, kGrayPhaseShift) ---
  // Projected bits, MSB first, of the ceil(log2(L))-bit code of the
  // coordinate; 0 = all. With b of B bits a stripe is 2^(B-b) px wide.
  // kGrayPhaseShift: the phase period equals the stripe width.
  int gray_bits = 0;
  // Or the stripe width itself, projector px (> 0; >= 4 for
  // kGrayPhaseShift, where it is the phase period), for pitches that are not
  // a power of two (60 px, say): the code then has ceil(log2(ceil(L /
  // pitch))) bits and names the stripe floor((p + 0.5) / pitch); the last
  // stripe may be cut by the projector's edge. 0 = from gray_bits.
  double gray_pitch_px = 0;
  bool gray_inverse = false;      // each bit followed by its inverse
  bool reference_frames = true;   // full white then black before the bits
  bool complementary = false;     // kGrayPhaseShift: one extra bit of half a stripe

  // Optional capture layout: captured frame i (of one full sequence) shows
  // canonical frame frame_order[i] (canonical order as documented above and
  // in README.md), or is not part of the code when frame_order[i] is
  // kSkippedFrame (an extra white or black frame, say). Every canonical frame
  // appears exactly once. Empty = canonical order, nothing skipped.
  std::vector<int> frame_order;

  // Frames of one captured sequence (both directions for kBoth), skipped
  // frames included: what a decoder takes and a projector shows.
  int frameCount() const;
  // Frames of the code alone (canonical frames, both directions).
  int codeFrameCount() const;
  // Frames of one direction.
  int framesPerDirection() const;
  // kModulatedPhaseShift: whether set j (listed order) carries the carrier.
  bool setModulated(std::size_t j) const { return modulated_sets.empty() || modulated_sets.at(j); }
  // kMicroPhaseShift: the shift (rad) of further frequency j >= 1.
  double furtherPhase(std::size_t j) const {
    return further_phases_rad.empty() ? start_phase_rad : further_phases_rad.at(j - 1);
  }
  // Extent (px) of the encoded axis: width for columns, height for rows.
  int axisLength(bool columns) const { return columns ? projector_width : projector_height; }
  // Gray code: bits of the full code of an axis of L px, and the bits used.
  static int fullGrayBits(int axis_length);
  int grayBitsUsed(int axis_length) const;
  // Width (px) of a Gray stripe (= phase period for kGrayPhaseShift).
  double stripeWidth(int axis_length) const;
  // Period (px) of the finest sinusoid along an axis of L px (0 for kGrayCode).
  double finestPeriod(int axis_length) const;
  // kMicroPhaseShift: the smallest summed squared difference of the further
  // frequencies' cosines between a coordinate and any other candidate period
  // of the first frequency (over the encoded axes at 0.5 px steps). A pixel
  // picks the right period with a 5-sigma margin when 2 * 5 * sigma_c <=
  // sqrt(separation), sigma_c = sigma_I / B (see derivedMinModulation()).
  double microSeparation() const;

  // Throws PatternSpecError naming the pattern and the bad field. Besides the
  // ranges of every field, the unwrapping margin of phase-shift patterns is
  // checked: a frequency step whose fringe order cannot be picked reliably
  // (derivedMinModulation() above half the modulation an 8-bit camera can
  // record, 255 * amplitude / 2 DN) is refused with the numbers.
  void validate() const;
};

// The PatternSpec of the paper's 3+3 (phase shift, 3 steps, frequencies
// {fringes, 1}, hierarchical unwrapping).
PatternSpec toSpec(const PhaseShift33Pattern& p);

// Relative projector intensity in [0, 1] of projected frame `frame` at the
// continuous projector coordinate (u, v) (px). Gray stripes are sharp;
// skipped frames (kSkippedFrame) are black.
// Throws std::out_of_range for a frame outside [0, frameCount()).
double patternIntensity(const PatternSpec& spec, int frame, double u, double v);

// The projector images (CV_8UC1, projector_height x projector_width) in
// projection order: round(255 * intensity) at each pixel centre.
std::vector<cv::Mat> generatePatternImages(const PatternSpec& spec);

}  // namespace sl::pipeline
