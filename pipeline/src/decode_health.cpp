// Decode health: counts of the status map, the residual distribution of the
// modulated pixels, the modulation of each sinusoid set on a sparse grid.
#include "sl/pipeline/decode_health.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <Eigen/LU>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "frame_layout.h"

namespace sl::pipeline {

namespace {

// Grid step (camera px, both axes) of the modulation-per-frequency estimate.
constexpr int kModulationGridStep = 4;

bool modulatedStatus(std::uint8_t s) {
  return s == static_cast<std::uint8_t>(PixelStatus::kValid) ||
         s == static_cast<std::uint8_t>(PixelStatus::kUnwrapInconsistent) ||
         s == static_cast<std::uint8_t>(PixelStatus::kOutOfRange);
}

// Value of `sorted` at quantile q (nearest rank).
double quantile(const std::vector<float>& sorted, double q) {
  if (sorted.empty()) return 0;
  const auto i = static_cast<std::size_t>(std::clamp(q * double(sorted.size() - 1), 0.0,
                                                     double(sorted.size() - 1)));
  return sorted[i];
}

// One N-step set (equally spaced shifts) of one direction: the captured
// frames of each shift, summed over carrier shifts (modulated phase shift:
// the three carrier phases add up to a constant 1.5 times the sinusoid).
struct SinusoidSet {
  bool columns = true;
  double frequency = 0;
  std::vector<double> deltas;
  std::vector<std::vector<int>> frames;  // per delta: captured frame indices
};

std::vector<SinusoidSet> sinusoidSets(const PatternSpec& spec) {
  const auto canonical = detail::canonicalFrames(spec);
  std::vector<int> position(canonical.size(), -1);
  for (int i = 0; i < spec.frameCount(); ++i) {
    const int c = spec.frame_order.empty() ? i : spec.frame_order[i];
    if (c != kSkippedFrame) position[static_cast<std::size_t>(c)] = i;
  }
  std::vector<SinusoidSet> sets;
  for (std::size_t c = 0; c < canonical.size(); ++c) {
    const detail::FrameInfo& f = canonical[c];
    if (f.kind != detail::FrameInfo::Kind::kSinusoid) continue;
    auto set = std::find_if(sets.begin(), sets.end(), [&](const SinusoidSet& s) {
      return s.columns == f.columns && s.frequency == f.frequency;
    });
    if (set == sets.end()) {
      sets.push_back(SinusoidSet{f.columns, f.frequency, {}, {}});
      set = sets.end() - 1;
    }
    auto d = std::find(set->deltas.begin(), set->deltas.end(), f.delta);
    if (d == set->deltas.end()) {
      set->deltas.push_back(f.delta);
      set->frames.emplace_back();
      d = set->deltas.end() - 1;
    }
    set->frames[static_cast<std::size_t>(d - set->deltas.begin())].push_back(position[c]);
  }
  // Only sets whose shifts are equally spaced over 2 pi (N >= 3) give B
  // from the first harmonic alone; 2+1 pairs and single micro frames do not.
  std::erase_if(sets, [&](const SinusoidSet& s) {
    return s.deltas.size() < 3 || spec.family == PatternFamily::kTwoPlusOne;
  });
  return sets;
}

template <typename Pixel>
std::vector<FrequencyModulation> modulationPerSet(const std::vector<SinusoidSet>& sets,
                                                  const std::vector<cv::Mat>& frames,
                                                  const cv::Mat& status, double dn_scale) {
  std::vector<FrequencyModulation> out;
  for (const SinusoidSet& s : sets) {
    const int n = static_cast<int>(s.deltas.size());
    std::vector<double> ws(n), wc(n);
    for (int m = 0; m < n; ++m) {
      ws[m] = std::sin(s.deltas[m]) / static_cast<double>(s.frames[m].size());
      wc[m] = std::cos(s.deltas[m]) / static_cast<double>(s.frames[m].size());
    }
    std::vector<float> b;
    for (int y = 0; y < status.rows; y += kModulationGridStep) {
      const auto* st = status.ptr<std::uint8_t>(y);
      for (int x = 0; x < status.cols; x += kModulationGridStep) {
        if (!modulatedStatus(st[x])) continue;
        double sv = 0, cv = 0;
        for (int m = 0; m < n; ++m) {
          double v = 0;
          for (int i : s.frames[m]) v += frames[static_cast<std::size_t>(i)].ptr<Pixel>(y)[x];
          sv += ws[m] * v;
          cv += wc[m] * v;
        }
        b.push_back(static_cast<float>(2.0 / n * std::hypot(sv, cv) / dn_scale));
      }
    }
    std::sort(b.begin(), b.end());
    out.push_back(FrequencyModulation{s.columns, s.frequency, quantile(b, 0.5)});
  }
  return out;
}

std::string percent(double fraction) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f %%", 100.0 * fraction);
  return text;
}

std::string fixed(double v, int digits) {
  char text[32];
  std::snprintf(text, sizeof text, "%.*f", digits, v);
  return text;
}

// The judgement of `h` (counts and residual quantiles filled in) against
// `limits`: problems, warnings, implausible.
void judge(const PatternSpec& spec, const DecodeHealthLimits& limits, DecodeHealth& h) {
  const std::int64_t modulated = h.modulated();
  if (modulated < limits.min_modulated_pixels) {
    h.warnings.push_back(std::to_string(modulated) + " modulated pixels (fewer than " +
                         std::to_string(limits.min_modulated_pixels) +
                         "): too few to judge whether the pattern description fits the frames");
  } else if (h.has_residual) {
    if (h.inconsistentFraction() > limits.max_inconsistent_fraction)
      h.problems.push_back(percent(h.inconsistentFraction()) +
                           " of modulated pixels fail unwrapping (limit " +
                           percent(limits.max_inconsistent_fraction) +
                           "): does the pattern file match the projected sequence "
                           "(frequencies and their order, steps, frame order), and is the "
                           "projector's response compensated (decoder.projector_gamma)?");
    if (h.residual_median > limits.max_median_residual)
      h.problems.push_back("median unwrapping residual " + fixed(h.residual_median, 3) +
                           " (limit " + fixed(limits.max_median_residual, 3) +
                           "; 0.25 is what a description that does not fit the frames gives)");
  }
  if (modulated >= limits.min_modulated_pixels &&
      h.outOfRangeFraction() > limits.max_out_of_range_fraction)
    h.problems.push_back(percent(h.outOfRangeFraction()) +
                         " of modulated pixels decode outside the projector (limit " +
                         percent(limits.max_out_of_range_fraction) +
                         "): is the fringe pitch, period or projector size of the pattern file "
                         "the projected one?");
  if (h.saturatedFraction() > limits.max_saturated_fraction)
    h.warnings.push_back(percent(h.saturatedFraction()) +
                         " of pixels saturated (limit " + percent(limits.max_saturated_fraction) +
                         "): lower the exposure, or decode them anyway with --keep-saturated");
  if (!h.has_residual)
    h.warnings.push_back("pattern '" + spec.name +
                         "' has no consistency test (one frequency, or Gray code without the "
                         "complementary bit): a wrong description cannot be seen in one scan");
  h.implausible = !h.problems.empty();
}

}  // namespace

double DecodeHealth::modulatedFraction() const {
  return pixels > 0 ? double(modulated()) / double(pixels) : 0.0;
}
double DecodeHealth::consistentFraction() const {
  return modulated() > 0 ? double(valid + out_of_range) / double(modulated()) : 0.0;
}
double DecodeHealth::inconsistentFraction() const {
  return modulated() > 0 ? double(inconsistent) / double(modulated()) : 0.0;
}
double DecodeHealth::outOfRangeFraction() const {
  return modulated() > 0 ? double(out_of_range) / double(modulated()) : 0.0;
}
double DecodeHealth::saturatedFraction() const {
  return pixels > 0 ? double(saturated) / double(pixels) : 0.0;
}

bool hasConsistencyTest(const PatternSpec& spec) {
  switch (spec.family) {
    case PatternFamily::kPhaseShift:
    case PatternFamily::kTwoPlusOne:
    case PatternFamily::kModulatedPhaseShift:
      return spec.frequencies.size() >= 2;
    case PatternFamily::kMicroPhaseShift:
      return true;
    case PatternFamily::kGrayPhaseShift:
      return spec.complementary;
    case PatternFamily::kGrayCode:
      return false;
  }
  return false;
}

namespace {

// Adds to n[k] the count of bytes equal to k (k = 0..3) in st[0, width).
void countStatusRow(const std::uint8_t* st, int width, std::uint32_t* n) {
  int x = 0;
#if defined(__SSE2__)
  // Byte lanes count up to 255 compares, then are summed (sad against 0).
  const __m128i zero = _mm_setzero_si128();
  const __m128i k[4] = {_mm_set1_epi8(0), _mm_set1_epi8(1), _mm_set1_epi8(2), _mm_set1_epi8(3)};
  while (x + 16 <= width) {
    __m128i a[4] = {zero, zero, zero, zero};
    for (int i = 0; i < 255 && x + 16 <= width; ++i, x += 16) {
      const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(st + x));
      for (int c = 0; c < 4; ++c) a[c] = _mm_sub_epi8(a[c], _mm_cmpeq_epi8(v, k[c]));
    }
    for (int c = 0; c < 4; ++c) {
      const __m128i s = _mm_sad_epu8(a[c], zero);
      n[c] += static_cast<std::uint32_t>(_mm_cvtsi128_si32(s) + _mm_extract_epi16(s, 4));
    }
  }
#endif
  for (; x < width; ++x)
    if (st[x] < 4) ++n[st[x]];
}

}  // namespace

void DecodeTally::addRows(const ProjectorMaps& maps, int row_begin, int row_end, bool with_residual,
                          int image_row) {
  const int width = maps.status.cols;
  for (int y = row_begin; y < row_end; ++y) {
    const auto* st = maps.status.ptr<std::uint8_t>(y);
    std::uint32_t n[4] = {0, 0, 0, 0};  // the first four codes; the rest is 4
    countStatusRow(st, width, n);
    status[0] += n[0];
    status[1] += n[1];
    status[2] += n[2];
    status[3] += n[3];
    status[4] += static_cast<std::int64_t>(width) - n[0] - n[1] - n[2] - n[3];
    if (!with_residual || (image_row + (y - row_begin)) % kResidualStep != 0) continue;
    const float* r = maps.residual.ptr<float>(y);
    for (int x = 0; x < width; x += kResidualStep) {
      // Valid (0), inconsistent (3) and out of range (4) are modulated.
      if (st[x] == 1 || st[x] == 2) continue;
      const float bin = r[x] * static_cast<float>(1.0 / kBinWidth);
      // NaN and anything from 0.5 up land in the last bin.
      const int b = bin >= 0.0f && bin < static_cast<float>(kBins) ? static_cast<int>(bin) : kBins;
      ++residual[static_cast<std::size_t>(b)];
    }
  }
}

void DecodeTally::add(const DecodeTally& other) {
  for (std::size_t i = 0; i < status.size(); ++i) status[i] += other.status[i];
  for (std::size_t i = 0; i < residual.size(); ++i) residual[i] += other.residual[i];
}

namespace {

// Quantile q of the tally's residuals, linear within the bin it falls in
// (the last bin, >= 0.5, counts as 0.5).
double tallyQuantile(const DecodeTally& t, std::int64_t total, double q) {
  const double rank = q * static_cast<double>(total);
  double below = 0;
  for (int b = 0; b < DecodeTally::kBins; ++b) {
    const double n = static_cast<double>(t.residual[static_cast<std::size_t>(b)]);
    if (below + n >= rank && n > 0) return (b + (rank - below) / n) * DecodeTally::kBinWidth;
    below += n;
  }
  return DecodeTally::kBins * DecodeTally::kBinWidth;
}

}  // namespace

DecodeHealth judgeDecodeTally(const PatternSpec& spec, const DecoderOptions& options,
                              const DecodeTally& t, const DecodeHealthLimits& limits) {
  DecodeHealth h;
  h.has_residual = hasConsistencyTest(spec);
  h.max_unwrap_error = options.max_unwrap_error;
  h.valid = t.status[0];
  h.low_modulation = t.status[1];
  h.saturated = t.status[2];
  h.inconsistent = t.status[3];
  h.out_of_range = t.status[4];
  h.pixels = h.valid + h.low_modulation + h.saturated + h.inconsistent + h.out_of_range;
  std::int64_t total = 0;
  for (std::int64_t n : t.residual) total += n;
  if (h.has_residual && total > 0) {
    // Ten fine bins per coarse one (0.05 / 0.005); the last is >= 0.5.
    for (int b = 0; b <= DecodeTally::kBins; ++b)
      h.residual_histogram[static_cast<std::size_t>(std::min(b / 10, 10))] +=
          static_cast<double>(t.residual[static_cast<std::size_t>(b)]) / static_cast<double>(total);
    h.residual_median = tallyQuantile(t, total, 0.5);
    h.residual_p90 = tallyQuantile(t, total, 0.9);
  }
  judge(spec, limits, h);
  return h;
}

DecodeHealth measureDecodeHealth(const PatternSpec& spec, const DecoderOptions& options,
                                 const ProjectorMaps& maps, const std::vector<cv::Mat>& frames,
                                 int bit_depth, const DecodeHealthLimits& limits) {
  if (maps.status.empty() || maps.status.type() != CV_8UC1 || maps.residual.type() != CV_32FC1 ||
      maps.residual.size() != maps.status.size())
    throw std::invalid_argument("measureDecodeHealth: maps without status or residual");
  if (static_cast<int>(frames.size()) != spec.frameCount())
    throw std::invalid_argument("measureDecodeHealth: " + std::to_string(frames.size()) +
                                " frames for pattern '" + spec.name + "' of " +
                                std::to_string(spec.frameCount()));
  for (const cv::Mat& f : frames)
    if (f.size() != maps.status.size() || (f.type() != CV_8UC1 && f.type() != CV_16UC1) ||
        f.type() != frames.front().type())
      throw std::invalid_argument("measureDecodeHealth: frames differ from the maps");

  DecodeHealth h;
  h.has_residual = hasConsistencyTest(spec);
  h.max_unwrap_error = options.max_unwrap_error;
  std::int64_t counts[5] = {0, 0, 0, 0, 0};
  std::vector<float> residuals;
  for (int y = 0; y < maps.status.rows; ++y) {
    const auto* st = maps.status.ptr<std::uint8_t>(y);
    const auto* r = maps.residual.ptr<float>(y);
    for (int x = 0; x < maps.status.cols; ++x) {
      ++counts[std::min<int>(st[x], 4)];
      if (h.has_residual && modulatedStatus(st[x])) residuals.push_back(r[x]);
    }
  }
  h.pixels = static_cast<std::int64_t>(maps.status.total());
  h.valid = counts[0];
  h.low_modulation = counts[1];
  h.saturated = counts[2];
  h.inconsistent = counts[3];
  h.out_of_range = counts[4];
  if (!residuals.empty()) {
    for (float r : residuals) {
      const int bin = std::clamp(static_cast<int>(r / 0.05f), 0, 10);
      h.residual_histogram[static_cast<std::size_t>(bin)] += 1.0;
    }
    for (double& b : h.residual_histogram) b /= double(residuals.size());
    const auto mid = residuals.begin() + static_cast<std::ptrdiff_t>(residuals.size() / 2);
    std::nth_element(residuals.begin(), mid, residuals.end());
    h.residual_median = *mid;
    const auto p90 = residuals.begin() + static_cast<std::ptrdiff_t>(residuals.size() * 9 / 10);
    std::nth_element(residuals.begin(), p90, residuals.end());
    h.residual_p90 = *p90;
  }
  const auto sets = sinusoidSets(spec);
  const double dn_scale = std::ldexp(1.0, bit_depth - 8);
  h.modulation = frames.front().type() == CV_8UC1
                     ? modulationPerSet<std::uint8_t>(sets, frames, maps.status, dn_scale)
                     : modulationPerSet<std::uint16_t>(sets, frames, maps.status, dn_scale);

  judge(spec, limits, h);
  return h;
}

void addEpipolarCheck(DecodeHealth& health, const ProjectorMaps& maps,
                      const CameraProjectorCalibration& calibration, bool undistort_projector,
                      const DecodeHealthLimits& limits) {
  if (maps.up.empty() || maps.vp.empty() || maps.status.empty()) return;
  // Essential matrix of X_p = R X_c + t: a camera ray x_c (normalized) meets
  // the projector's normalized image on the line E x_c; in projector pixels
  // the line is K_p^-T E x_c.
  Eigen::Matrix3d tx;
  const Eigen::Vector3d& t = calibration.t;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  const Eigen::Matrix3d F = calibration.projector.K().inverse().transpose() * tx * calibration.R;
  const PinholeModel& camera = calibration.camera;
  const PinholeModel& projector = calibration.projector;
  const bool camera_distorted = camera.hasDistortion();
  const bool projector_distorted = undistort_projector && projector.hasDistortion();
  const Eigen::Matrix3d Kp = projector.K();
  std::vector<float> distance;
  for (int v = 0; v < maps.status.rows; ++v) {
    const auto* st = maps.status.ptr<std::uint8_t>(v);
    const float* up = maps.up.ptr<float>(v);
    const float* vp = maps.vp.ptr<float>(v);
    for (int u = 0; u < maps.status.cols; ++u) {
      if (st[u] != 0 || !std::isfinite(up[u]) || !std::isfinite(vp[u])) continue;
      const Eigen::Vector2d xn =
          camera_distorted ? camera.pixelToNormalized(Eigen::Vector2d(u, v))
                           : Eigen::Vector2d((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy);
      const Eigen::Vector3d line = F * Eigen::Vector3d(xn.x(), xn.y(), 1.0);
      Eigen::Vector3d q(up[u], vp[u], 1.0);
      if (projector_distorted) {
        const Eigen::Vector2d pn = projector.pixelToNormalized(Eigen::Vector2d(up[u], vp[u]));
        q = Kp * Eigen::Vector3d(pn.x(), pn.y(), 1.0);
      }
      const double norm = std::hypot(line.x(), line.y());
      if (!(norm > 0)) continue;
      distance.push_back(static_cast<float>(std::abs(line.dot(q)) / norm));
    }
  }
  if (distance.empty()) return;
  health.has_epipolar = true;
  health.epipolar_pixels = static_cast<std::int64_t>(distance.size());
  std::sort(distance.begin(), distance.end());
  health.epipolar_median_px = quantile(distance, 0.5);
  health.epipolar_p90_px = quantile(distance, 0.9);
  if (health.epipolar_pixels >= limits.min_epipolar_pixels &&
      health.epipolar_median_px > limits.max_epipolar_median_px) {
    health.problems.push_back(
        "decoded projector coordinates lie a median " + fixed(health.epipolar_median_px, 1) +
        " px off the epipolar lines of the calibration (limit " +
        fixed(limits.max_epipolar_median_px, 1) +
        " px): is the fringe pitch or period of the pattern file the projected one, and is the "
        "calibration the rig's?");
    health.implausible = true;
  }
}

std::string describeDecodeHealth(const DecodeHealth& h, const std::string& prefix) {
  std::ostringstream o;
  o << prefix << "pixels " << h.pixels << ": " << h.valid << " valid, " << h.low_modulation
    << " low modulation, " << h.saturated << " saturated, " << h.inconsistent
    << " unwrap inconsistent, " << h.out_of_range << " out of range\n";
  o << prefix << "modulated " << percent(h.modulatedFraction()) << " of pixels; of those "
    << percent(h.consistentFraction()) << " unwrap consistently, "
    << percent(h.outOfRangeFraction()) << " out of range\n";
  if (h.has_residual) {
    o << prefix << "unwrapping residual median " << fixed(h.residual_median, 3) << ", p90 "
      << fixed(h.residual_p90, 3) << " (bound " << fixed(h.max_unwrap_error, 2)
      << "); per 0.05 bin:";
    for (double b : h.residual_histogram) o << " " << fixed(100.0 * b, 1);
    o << " %\n";
  }
  if (h.has_epipolar)
    o << prefix << "epipolar distance of (up, vp), " << h.epipolar_pixels << " pixels: median "
      << fixed(h.epipolar_median_px, 2) << " px, p90 " << fixed(h.epipolar_p90_px, 2) << " px\n";
  if (!h.modulation.empty()) {
    o << prefix << "modulation B (8-bit DN, median):";
    for (const FrequencyModulation& m : h.modulation)
      o << " " << (m.columns ? "u" : "v") << "@" << m.frequency << " " << fixed(m.median_b_dn, 1);
    o << "\n";
  }
  for (const std::string& p : h.problems) o << prefix << "IMPLAUSIBLE: " << p << "\n";
  for (const std::string& w : h.warnings) o << prefix << "warning: " << w << "\n";
  return o.str();
}

}  // namespace sl::pipeline
