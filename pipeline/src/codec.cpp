// Codec base: frame checks, buffer handling, the per-row driver that feeds
// each direction's canonical frames to the family's row kernel and combines
// the two directions of kBoth; the factory.
#include "sl/pipeline/codec.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "codec_families.h"
#include "frame_layout.h"
#include "sl/pipeline/multiversion.h"
#include "sl/pipeline/projector_response.h"

namespace sl::pipeline {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

void ensureMap(cv::Mat& m, cv::Size size, int type, bool* allocated = nullptr) {
  if (m.size() != size || m.type() != type || !m.isContinuous() || m.empty()) {
    m.create(size, type);
    if (allocated) *allocated = true;
  }
}

// coord = NaN where status != 0 (one direction).
SL_MULTIVERSION void nanWhereInvalid(int width, const std::uint8_t* __restrict status,
                                     float* __restrict coord) {
  for (int x = 0; x < width; ++x) coord[x] = status[x] == 0 ? coord[x] : kNaN;
}

// kBoth: a pixel is valid where both directions are; B is the smaller one,
// the residual the larger.
SL_MULTIVERSION void combineDirections(int width, std::uint8_t* __restrict status,
                                       float* __restrict modulation, float* __restrict residual,
                                       float* __restrict up, float* __restrict vp,
                                       const std::uint8_t* __restrict status2,
                                       const float* __restrict mod2,
                                       const float* __restrict residual2,
                                       const float* __restrict coord2) {
  for (int x = 0; x < width; ++x) {
    const std::uint8_t s = status[x] != 0 ? status[x] : status2[x];
    status[x] = s;
    modulation[x] = std::min(modulation[x], mod2[x]);
    residual[x] = std::max(residual[x], residual2[x]);
    up[x] = s == 0 ? up[x] : kNaN;
    vp[x] = s == 0 ? coord2[x] : kNaN;
  }
}

}  // namespace

float derivedMinModulation(const PatternSpec& spec, float max_unwrap_error) {
  constexpr double kNoiseDn = 0.54;      // sigma_I near the threshold (codec.h)
  constexpr double kMarginSigmas = 5.0;  // z
  constexpr double kFloorDn = 8.0;
  double phase_gain = 0;  // sigma_phi * B / sigma_I of one set
  if (spec.family == PatternFamily::kMicroPhaseShift) {
    // The closest wrong candidate's cost differs by the separation d, with a
    // noise of 2 sigma_c sqrt(d), sigma_c = sigma_I / B per cosine.
    const double d = spec.microSeparation();
    if (!(d > 0)) return std::numeric_limits<float>::infinity();
    return static_cast<float>(std::max(kFloorDn, 2.0 * kMarginSigmas * kNoiseDn / std::sqrt(d)));
  }
  if (spec.family == PatternFamily::kPhaseShift ||
      spec.family == PatternFamily::kModulatedPhaseShift)
    phase_gain = std::sqrt(2.0 / spec.steps);
  else if (spec.family == PatternFamily::kTwoPlusOne) phase_gain = std::sqrt(2.0);
  else return static_cast<float>(kFloorDn);
  std::vector<double> f = spec.frequencies;
  std::sort(f.begin(), f.end(), std::greater<>());
  double amplification = 0;  // largest sqrt(r^2 v_coarse + v_fine) over the steps
  if (spec.unwrapping == Unwrapping::kHeterodyne) {
    // Level l: beats of neighbouring level l - 1 phases; the codec unwraps
    // the first item of each level with the first of the next.
    auto binomial = [](int n, int k) {
      double c = 1;
      for (int i = 1; i <= k; ++i) c = c * (n - k + i) / i;
      return c;
    };
    std::vector<double> level = f;
    for (int l = 0; level.size() > 1; ++l) {
      std::vector<double> next;
      for (std::size_t i = 0; i + 1 < level.size(); ++i) next.push_back(level[i] - level[i + 1]);
      const double r = level[0] / next[0];
      amplification = std::max(amplification, std::sqrt(r * r * binomial(2 * l + 2, l + 1) +
                                                         binomial(2 * l, l)));
      level = next;
    }
  } else {
    for (std::size_t i = 0; i + 1 < f.size(); ++i) {
      const double r = f[i] / f[i + 1];
      amplification = std::max(amplification, std::sqrt(r * r + 1));
    }
  }
  const double b = kMarginSigmas * phase_gain * amplification * kNoiseDn /
                   (2 * std::numbers::pi * (1.0 - max_unwrap_error));
  return static_cast<float>(std::max(kFloorDn, b));
}

Codec::Codec(PatternSpec spec, DecoderOptions options)
    : spec_(std::move(spec)), options_(options) {
  spec_.validate();
  if (!(options_.max_unwrap_error > 0.0f && options_.max_unwrap_error <= 0.5f))
    throw std::invalid_argument("DecoderOptions: max_unwrap_error must be in (0, 0.5]");
  if (options_.min_modulation < 0.0f)
    options_.min_modulation = derivedMinModulation(spec_, options_.max_unwrap_error);
  if (!options_.projector_response.empty()) validateProjectorResponse(options_.projector_response);
  if (!(options_.min_modulation >= 0.0f))
    throw std::invalid_argument("DecoderOptions: min_modulation must be >= 0 (or negative: derived)");
  const int n = spec_.frameCount();
  position_.resize(spec_.codeFrameCount());
  for (int i = 0; i < n; ++i) {
    const int canonical = spec_.frame_order.empty() ? i : spec_.frame_order[i];
    if (canonical != kSkippedFrame) position_[canonical] = i;
  }
}

void Codec::checkFrames(const std::vector<cv::Mat>& frames, int bit_depth) const {
  auto who = [&] { return "Codec '" + spec_.name + "'"; };
  if (static_cast<int>(frames.size()) != frameCount()) {
    throw std::invalid_argument(who() + ": expected " + std::to_string(frameCount()) +
                                " frames, got " + std::to_string(frames.size()));
  }
  const cv::Mat& first = frames.front();
  if (first.empty()) throw std::invalid_argument(who() + ": frame 0 is empty");
  if (first.type() != CV_8UC1 && first.type() != CV_16UC1)
    throw std::invalid_argument(who() + ": frames must be CV_8UC1 or CV_16UC1");
  for (std::size_t i = 1; i < frames.size(); ++i) {
    if (frames[i].size() != first.size())
      throw std::invalid_argument(who() + ": frame " + std::to_string(i) +
                                  " differs in size from frame 0");
    if (frames[i].type() != first.type())
      throw std::invalid_argument(who() + ": frame " + std::to_string(i) +
                                  " differs in type from frame 0");
  }
  const int max_bits = first.type() == CV_8UC1 ? 8 : 16;
  if (bit_depth < 1 || bit_depth > max_bits)
    throw std::invalid_argument(who() + ": bit_depth " + std::to_string(bit_depth) +
                                " is outside 1.." + std::to_string(max_bits) +
                                " for this image type");
}

void Codec::prepare(const std::vector<cv::Mat>& frames, int bit_depth, ProjectorMaps& out) const {
  checkFrames(frames, bit_depth);
  const cv::Mat& first = frames.front();
  const cv::Size size = first.size();
  bool up_new = false, vp_new = false;
  ensureMap(out.up, size, CV_32FC1, &up_new);
  ensureMap(out.vp, size, CV_32FC1, &vp_new);
  ensureMap(out.modulation, size, CV_32FC1);
  ensureMap(out.offset, size, CV_32FC1);
  ensureMap(out.status, size, CV_8UC1);
  ensureMap(out.residual, size, CV_32FC1);
  // The map of an axis the pattern does not encode is never written by
  // decodeRows(): NaN it when it is (re)allocated. Reusing `out` with a codec
  // of another direction therefore needs a fresh ProjectorMaps.
  if (spec_.direction == Direction::kVertical && up_new) out.up.setTo(kNaN);
  if (spec_.direction == Direction::kHorizontal && vp_new) out.vp.setTo(kNaN);
}

void Codec::decodeInto(const std::vector<cv::Mat>& frames, int bit_depth,
                       ProjectorMaps& out) const {
  prepare(frames, bit_depth, out);
  decodeRows(frames, bit_depth, 0, frames.front().rows, out);
}

ProjectorMaps Codec::decode(const std::vector<cv::Mat>& frames, int bit_depth) const {
  ProjectorMaps maps;
  decodeInto(frames, bit_depth, maps);
  return maps;
}

void Codec::decodeBand(const std::vector<cv::Mat>& frames, int bit_depth, int row_begin,
                       int row_end, ProjectorMaps& band) const {
  checkFrames(frames, bit_depth);
  const int width = frames.front().cols;
  if (row_begin < 0 || row_end > frames.front().rows || row_begin > row_end)
    throw std::invalid_argument("Codec '" + spec_.name + "': decodeBand rows [" +
                                std::to_string(row_begin) + ", " + std::to_string(row_end) +
                                ") outside the frames");
  const int rows = std::max(row_end - row_begin, 1);
  auto ensureBand = [&](cv::Mat& m, int type) {
    const bool fits = m.cols == width && m.rows >= rows && m.type() == type && m.isContinuous();
    if (!fits) m.create(std::max(rows, m.cols == width ? m.rows : 0), width, type);
    return !fits;
  };
  const bool up_new = ensureBand(band.up, CV_32FC1);
  const bool vp_new = ensureBand(band.vp, CV_32FC1);
  ensureBand(band.modulation, CV_32FC1);
  ensureBand(band.offset, CV_32FC1);
  ensureBand(band.status, CV_8UC1);
  ensureBand(band.residual, CV_32FC1);
  if (spec_.direction == Direction::kVertical && up_new) band.up.setTo(kNaN);
  if (spec_.direction == Direction::kHorizontal && vp_new) band.vp.setTo(kNaN);
  decodeRowsTo(frames, bit_depth, row_begin, row_end, band, 0);
}

void Codec::decodeRows(const std::vector<cv::Mat>& frames, int bit_depth, int row_begin,
                       int row_end, ProjectorMaps& out) const {
  decodeRowsTo(frames, bit_depth, row_begin, row_end, out, row_begin);
}

void Codec::decodeRowsTo(const std::vector<cv::Mat>& frames, int bit_depth, int row_begin,
                         int row_end, ProjectorMaps& out, int out_row) const {
  const int width = frames.front().cols;
  const bool eight = frames.front().type() == CV_8UC1;
  const int per_direction = spec_.framesPerDirection();
  const bool both = spec_.direction == Direction::kBoth;
  const float dn_scale = std::ldexp(1.0f, bit_depth - 8);
  const float saturation = options_.reject_saturated ? static_cast<float>((1 << bit_depth) - 1)
                                                     : std::numeric_limits<float>::infinity();
  // Row buffers, left uninitialized (the kernels write before they read;
  // zeroing them would cost a share of a decode; docs/measurements.md).
  const auto scratch =
      std::make_unique_for_overwrite<float[]>(static_cast<std::size_t>(scratchRows()) * width);
  // Second direction of kBoth: coordinate, B, A, status, residual.
  const std::size_t width2 = both ? width : 0;
  const auto coord2 = std::make_unique_for_overwrite<float[]>(width2);
  const auto mod2 = std::make_unique_for_overwrite<float[]>(width2);
  const auto off2 = std::make_unique_for_overwrite<float[]>(width2);
  const auto status2 = std::make_unique_for_overwrite<std::uint8_t[]>(width2);
  const auto residual2 = std::make_unique_for_overwrite<float[]>(width2);
  std::vector<const void*> rows(per_direction);

  auto context = [&](bool columns) {
    return RowContext{columns, static_cast<float>(spec_.axisLength(columns)), dn_scale, saturation,
                      scratch.get()};
  };
  auto runRow = [&](int direction, int y, const RowContext& c, const RowOutput& o) {
    for (int i = 0; i < per_direction; ++i)
      rows[i] = frames[position_[direction * per_direction + i]].ptr(y);
    if (eight) {
      decodeRow8(c, reinterpret_cast<const std::uint8_t* const*>(rows.data()), width, o);
    } else {
      decodeRow16(c, reinterpret_cast<const std::uint16_t* const*>(rows.data()), width, o);
    }
  };

  const bool first_columns = spec_.direction != Direction::kVertical;
  const RowContext first_ctx = context(first_columns);
  const RowContext second_ctx = context(false);
  for (int y = row_begin; y < row_end; ++y) {
    const int yo = y - row_begin + out_row;
    float* coord = (first_columns ? out.up : out.vp).ptr<float>(yo);
    float* modulation = out.modulation.ptr<float>(yo);
    float* offset = out.offset.ptr<float>(yo);
    std::uint8_t* status = out.status.ptr<std::uint8_t>(yo);
    float* residual = out.residual.ptr<float>(yo);
    runRow(0, y, first_ctx, RowOutput{coord, modulation, offset, status, residual});
    if (!both) {
      nanWhereInvalid(width, status, coord);
      continue;
    }
    runRow(1, y, second_ctx,
           RowOutput{coord2.get(), mod2.get(), off2.get(), status2.get(), residual2.get()});
    combineDirections(width, status, modulation, residual, coord, out.vp.ptr<float>(yo),
                      status2.get(), mod2.get(), residual2.get(), coord2.get());
  }
}

std::unique_ptr<Codec> makeCodec(const PatternSpec& spec, const DecoderOptions& options) {
  spec.validate();
  switch (spec.family) {
    case PatternFamily::kPhaseShift:
    case PatternFamily::kTwoPlusOne:
      return detail::makePhaseShiftCodec(spec, options);
    case PatternFamily::kGrayCode:
    case PatternFamily::kGrayPhaseShift:
      return detail::makeGrayCodec(spec, options);
    case PatternFamily::kMicroPhaseShift:
      return detail::makeMicroPhaseShiftCodec(spec, options);
    case PatternFamily::kModulatedPhaseShift:
      return detail::makeModulatedPhaseShiftCodec(spec, options);
  }
  throw std::invalid_argument("makeCodec: unknown family");
}

}  // namespace sl::pipeline
