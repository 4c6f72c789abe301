// Pattern codecs: one object per PatternSpec that generates the projector
// images and decodes camera images of the pattern into projector maps.
// Created by makeCodec() for every PatternFamily.
#pragma once

#include <memory>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// DecoderOptions::min_modulation that asks for derivedMinModulation().
inline constexpr float kDerivedMinModulation = -1.0f;

struct DecoderOptions {
  // Fringe amplitude B in DN on the 8-bit scale (scaled by 2^(bit_depth-8))
  // below which a pixel is kLowModulation (phase shift: the smallest B of
  // the frequencies). Gray code: half the white-black difference (or of a
  // bit and its inverse without reference frames). Negative (the default):
  // derivedMinModulation(spec, max_unwrap_error), resolved when the codec is
  // made (Codec::options() holds the value in use).
  float min_modulation = kDerivedMinModulation;
  bool reject_saturated = true;   // any frame at (2^bit_depth - 1) invalidates the pixel
  // Temporal unwrapping: |r * Phi_coarse - phi_fine - 2*pi*k| / (2*pi) above
  // this (periods of the finer frequency) marks kUnwrapInconsistent. Gray +
  // phase shift with the complementary bit: periods by which the phase may
  // lie outside the half stripe the code names. In (0, 0.5].
  float max_unwrap_error = 0.3f;
  // The projector's intensity response R(L) sampled at L = k / (size - 1)
  // (projector_response.h; any affine scale), e.g. gammaResponse(2.2) for a
  // projector in video mode. Empty (the default): linear, nothing to
  // compensate. Otherwise every sinusoid set's phase (phase shift, 2+1, Gray +
  // phase shift) is corrected for R before unwrapping; 3+3 patterns then
  // leave their dedicated kernels for the general row.
  std::vector<float> projector_response;
};

// The modulation (8-bit DN) below which the temporal unwrapping of `spec`
// would pick wrong fringe orders (points off by a whole period) too often.
// An unwrapping step from a coarse phase to one r times finer compares
// e = (r Phi_coarse - phi_fine) / (2 pi), in fine periods, whose standard
// deviation for sets of modulation B and intensity noise sigma_I is
//   sigma_e = g sqrt(r^2 v_coarse + v_fine) sigma_I / (2 pi B)
// (g = sqrt(2/N) for N-step sets, sqrt(2) for a 2+1 quadrature pair; v = 1
// per set, and C(2l, l) for a level-l heterodyne beat, whose phase combines
// l + 1 sets). A wrong order passes the consistency test when |e| > 1 -
// max_unwrap_error; asking that margin to be z = 5 standard deviations on
// the step with the largest sigma_e gives
//   B_min = z g sqrt(r^2 v_coarse + v_fine) sigma_I / (2 pi (1 - max_unwrap_error))
// with sigma_I = 0.54 DN (the simulated IMX174-class camera at the A ~ 25 DN
// of pixels near the threshold). At least 8 DN; Gray-code families (no
// noise-amplifying step) get 8. The 40:1 3+3 with 0.3: 20 DN; 16:1: 8 DN.
float derivedMinModulation(const PatternSpec& spec, float max_unwrap_error);

// Thread-compatible and immutable after construction: decode(), decodeRows()
// and generate() are const and keep no state, so concurrent calls on one
// instance are safe (decodeRows() on disjoint row ranges of one output).
//
// Output contract of decode() (all maps of the camera's size):
// - up / vp: projector column / row in projector px, with the convention of
//   patternIntensity() (a camera pixel that sees the centre of projector
//   column c decodes to c). Codes that are periodic along the axis (phase
//   shift with a unit-frequency cue or unit beat) decode to [0, L); values
//   above L - 0.5 cannot be told from the half pixel left of column 0 and are
//   kOutOfRange. Gray codes decode to the centre of the stripe.
//   NaN where the pixel is not valid, and in a map the pattern does not encode.
// - modulation: B (camera DN) of the finest sinusoid (Gray code: half the
//   white - black contrast); for kBoth the smaller of the two directions.
// - offset: A (camera DN) of the first direction.
// - status: PixelStatus, the first failing test in the order saturated, low
//   modulation, unwrap inconsistency, out of range; for kBoth a pixel is
//   valid only when both directions are (otherwise up and vp are both NaN).
// - residual: the consistency residual behind kUnwrapInconsistent (types.h),
//   for decode health (decode_health.h).
class Codec {
 public:
  virtual ~Codec() = default;

  const PatternSpec& spec() const { return spec_; }
  const DecoderOptions& options() const { return options_; }
  int frameCount() const { return spec_.frameCount(); }

  // Projector images (CV_8UC1, projector size) in projection order.
  std::vector<cv::Mat> generate() const { return generatePatternImages(spec_); }

  // frames: frameCount() camera images in projection order, CV_8UC1 or
  // CV_16UC1, all of one size; bit_depth = significant bits (1..8 or 1..16).
  // Throws std::invalid_argument on a wrong count, type, size or depth.
  ProjectorMaps decode(const std::vector<cv::Mat>& frames, int bit_depth) const;

  // Buffer-reusing variant: checks the frames and (re)allocates the maps of
  // `out` only when their size or type differ, then decodes all rows.
  void decodeInto(const std::vector<cv::Mat>& frames, int bit_depth, ProjectorMaps& out) const;

  // Checks the frames and prepares `out` as decodeInto() does, decoding
  // nothing; then decodeRows() may fill disjoint row ranges, from several
  // threads if the caller wants (the codec starts none).
  void prepare(const std::vector<cv::Mat>& frames, int bit_depth, ProjectorMaps& out) const;
  // Decodes rows [row_begin, row_end) into `out` (prepared). No checks.
  void decodeRows(const std::vector<cv::Mat>& frames, int bit_depth, int row_begin, int row_end,
                  ProjectorMaps& out) const;

  // Band form for callers that keep only what they derive from the maps
  // (Triangulator::triangulateBand()): checks the frames as prepare() does,
  // then decodes camera rows [row_begin, row_end) into rows 0 .. (row_end -
  // row_begin) of `band`, whose maps are (re)allocated only when their width
  // or type differ or they have fewer rows (so one band is reused for all
  // blocks of a scan). Same map contract as decode() otherwise.
  void decodeBand(const std::vector<cv::Mat>& frames, int bit_depth, int row_begin, int row_end,
                  ProjectorMaps& band) const;

  // The check of decode() and the others: throws std::invalid_argument
  // (naming the codec and the frame) on a wrong count, type, size or depth.
  void checkFrames(const std::vector<cv::Mat>& frames, int bit_depth) const;

 protected:
  Codec(PatternSpec spec, DecoderOptions options);

  // Decodes one row of one direction. frames[i] points at row y of the
  // direction's i-th canonical frame. Writes coord (projector px, any value
  // where status != 0), B, A and status (PixelStatus) for `width` pixels.
  struct RowOutput {
    float* coord;
    float* modulation;
    float* offset;
    std::uint8_t* status;
    float* residual;  // ProjectorMaps::residual
  };
  struct RowContext {
    bool columns;       // the direction's axis
    float axis_length;  // L, projector px
    float dn_scale;     // 2^(bit_depth - 8)
    float saturation;   // 2^bit_depth - 1, or +inf when not rejecting
    float* scratch;     // scratchRows() rows of `width` floats, this call's own
  };
  // Rows of float scratch a row kernel needs.
  virtual int scratchRows() const = 0;
  virtual void decodeRow8(const RowContext& c, const std::uint8_t* const* frames, int width,
                          const RowOutput& out) const = 0;
  virtual void decodeRow16(const RowContext& c, const std::uint16_t* const* frames, int width,
                           const RowOutput& out) const = 0;

 private:
  // Rows [row_begin, row_end) of the frames into rows from out_row of `out`.
  void decodeRowsTo(const std::vector<cv::Mat>& frames, int bit_depth, int row_begin,
                    int row_end, ProjectorMaps& out, int out_row) const;

  PatternSpec spec_;
  DecoderOptions options_;
  std::vector<int> position_;  // canonical frame -> index in the projected sequence
};

// Creates the codec of spec.family. Throws std::invalid_argument on an
// invalid spec (PatternSpec::validate()) or invalid options.
std::unique_ptr<Codec> makeCodec(const PatternSpec& spec, const DecoderOptions& options);

}  // namespace sl::pipeline
