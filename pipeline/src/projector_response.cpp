#include "sl/pipeline/projector_response.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "frame_layout.h"
#include "phase_response.h"

namespace sl::pipeline {

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

template <typename Pixel>
double at(const cv::Mat& m, int r, int c) {
  return m.at<Pixel>(r, c);
}

double pixel(const cv::Mat& m, int r, int c) {
  return m.type() == CV_8UC1 ? at<std::uint8_t>(m, r, c) : at<std::uint16_t>(m, r, c);
}

void checkFrames(const std::vector<cv::Mat>& frames, int bit_depth, const char* who) {
  if (frames.empty()) throw std::invalid_argument(std::string(who) + ": no frames");
  for (const cv::Mat& f : frames) {
    if (f.type() != CV_8UC1 && f.type() != CV_16UC1)
      throw std::invalid_argument(std::string(who) + ": frames must be CV_8UC1 or CV_16UC1");
    if (f.size() != frames[0].size() || f.type() != frames[0].type())
      throw std::invalid_argument(std::string(who) + ": frames differ in size or type");
  }
  const int max_bits = frames[0].type() == CV_8UC1 ? 8 : 16;
  if (bit_depth < 1 || bit_depth > max_bits)
    throw std::invalid_argument(std::string(who) + ": bit_depth outside 1.." +
                                std::to_string(max_bits));
}

}  // namespace

std::vector<float> gammaResponse(double gamma, int samples) {
  if (!(gamma > 0) || !std::isfinite(gamma))
    throw std::invalid_argument("projector gamma must be finite and > 0");
  if (samples < 2) throw std::invalid_argument("a projector response needs >= 2 samples");
  std::vector<float> r(samples);
  for (int k = 0; k < samples; ++k)
    r[k] = static_cast<float>(std::pow(static_cast<double>(k) / (samples - 1), gamma));
  return r;
}

void validateProjectorResponse(const std::vector<float>& response) {
  if (response.size() < 2)
    throw std::invalid_argument("projector_response needs at least 2 samples (R at L = 0 .. 1)");
  for (std::size_t k = 0; k < response.size(); ++k) {
    if (!std::isfinite(response[k]))
      throw std::invalid_argument("projector_response sample " + std::to_string(k) +
                                  " is not finite");
    if (k > 0 && !(response[k] > response[k - 1]))
      throw std::invalid_argument("projector_response must increase strictly (sample " +
                                  std::to_string(k) + " does not)");
  }
}

std::vector<float> estimateProjectorResponse(const std::vector<cv::Mat>& frames,
                                             const std::vector<double>& levels, int bit_depth,
                                             double min_contrast_dn, int samples) {
  const char* who = "estimateProjectorResponse";
  checkFrames(frames, bit_depth, who);
  if (frames.size() != levels.size() || levels.size() < 3)
    throw std::invalid_argument(std::string(who) + ": need one frame per level, >= 3 levels");
  for (std::size_t k = 0; k < levels.size(); ++k) {
    if (!(levels[k] >= 0 && levels[k] <= 1))
      throw std::invalid_argument(std::string(who) + ": levels must be in [0, 1]");
    if (k > 0 && !(levels[k] > levels[k - 1]))
      throw std::invalid_argument(std::string(who) + ": levels must be ascending");
  }
  if (levels.back() - levels.front() < 0.5)
    throw std::invalid_argument(std::string(who) + ": the levels must span at least 0.5");
  if (samples < 2) throw std::invalid_argument(std::string(who) + ": samples must be >= 2");
  const double scale = std::ldexp(1.0, bit_depth - 8);
  const double saturation = std::ldexp(1.0, bit_depth) - 1;
  const int n = static_cast<int>(levels.size());
  std::vector<std::vector<double>> normalised(n);
  const cv::Mat& first = frames.front();
  const cv::Mat& last = frames.back();
  for (int r = 0; r < first.rows; ++r)
    for (int c = 0; c < first.cols; ++c) {
      const double lo = pixel(first, r, c), hi = pixel(last, r, c);
      if (hi - lo < min_contrast_dn * scale || hi >= saturation) continue;
      for (int k = 0; k < n; ++k) normalised[k].push_back((pixel(frames[k], r, c) - lo) / (hi - lo));
    }
  if (normalised[0].size() < 100)
    throw std::invalid_argument(std::string(who) + ": only " +
                                std::to_string(normalised[0].size()) +
                                " pixels with enough contrast (need 100)");
  std::vector<double> measured(n);
  for (int k = 0; k < n; ++k) {
    auto& v = normalised[k];
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    measured[k] = v[v.size() / 2];
  }
  // measured is R normalised to R(levels.front()) = 0, R(levels.back()) = 1:
  // an affine image of R, which the phase does not see. Resample uniformly.
  std::vector<float> response(samples);
  for (int s = 0; s < samples; ++s) {
    const double L = static_cast<double>(s) / (samples - 1);
    int k = 0;
    while (k + 2 < n && levels[k + 1] < L) ++k;
    const double f = (L - levels[k]) / (levels[k + 1] - levels[k]);
    response[s] = static_cast<float>(measured[k] + f * (measured[k + 1] - measured[k]));
  }
  try {
    validateProjectorResponse(response);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string(who) + ": the measured response is not increasing (" +
                                e.what() + "): too much noise or a saturated ramp");
  }
  return response;
}

GammaEstimate estimateProjectorGamma(const PatternSpec& spec, const std::vector<cv::Mat>& frames,
                                     int bit_depth, float min_modulation_dn) {
  const std::string who = "estimateProjectorGamma('" + spec.name + "')";
  spec.validate();
  if (spec.family != PatternFamily::kPhaseShift || spec.unwrapping != Unwrapping::kHierarchical ||
      spec.frequencies.size() < 2)
    throw std::invalid_argument(who + ": needs a phase-shift pattern with >= 2 frequencies and "
                                      "hierarchical unwrapping");
  checkFrames(frames, bit_depth, who.c_str());
  if (static_cast<int>(frames.size()) != spec.frameCount())
    throw std::invalid_argument(who + ": expected " + std::to_string(spec.frameCount()) +
                                " frames, got " + std::to_string(frames.size()));
  // Frames of the first direction's sets, as captured.
  const auto canonical = detail::canonicalFrames(spec);
  std::vector<int> position(spec.codeFrameCount());
  for (int i = 0; i < spec.frameCount(); ++i) {
    const int c = spec.frame_order.empty() ? i : spec.frame_order[i];
    if (c != kSkippedFrame) position[c] = i;
  }
  std::vector<double> frequency = spec.frequencies;
  std::sort(frequency.begin(), frequency.end());
  const int sets = static_cast<int>(frequency.size());
  std::vector<std::vector<int>> set_frames(sets);
  std::vector<std::vector<double>> set_deltas(sets);
  for (int i = 0; i < spec.framesPerDirection(); ++i) {
    const auto& f = canonical[i];
    for (int j = 0; j < sets; ++j)
      if (f.frequency == frequency[j]) {
        set_frames[j].push_back(position[i]);
        set_deltas[j].push_back(f.delta);
      }
  }
  // Measured phases of every usable pixel (every 2nd row and column).
  const double scale = std::ldexp(1.0, bit_depth - 8);
  const double saturation = std::ldexp(1.0, bit_depth) - 1;
  const double min_b = min_modulation_dn * scale;
  std::vector<std::vector<float>> psi(sets);
  const cv::Size size = frames[0].size();
  for (int r = 0; r < size.height; r += 2)
    for (int c = 0; c < size.width; c += 2) {
      float phases[16];
      bool usable = sets <= 16;
      for (int j = 0; usable && j < sets; ++j) {
        double s = 0, k = 0;
        for (std::size_t m = 0; m < set_frames[j].size(); ++m) {
          const double v = pixel(frames[set_frames[j][m]], r, c);
          if (v >= saturation) usable = false;
          s += std::sin(set_deltas[j][m]) * v;
          k += std::cos(set_deltas[j][m]) * v;
        }
        const double b = 2.0 / set_frames[j].size() * std::hypot(s, k);
        if (b < min_b) usable = false;
        double p = std::atan2(s, k);
        phases[j] = static_cast<float>(p < 0 ? p + kTwoPi : p);
      }
      if (!usable) continue;
      for (int j = 0; j < sets; ++j) psi[j].push_back(phases[j]);
    }
  GammaEstimate estimate;
  estimate.pixels = static_cast<long>(psi[0].size());
  if (estimate.pixels < 1000)
    throw std::invalid_argument(who + ": only " + std::to_string(estimate.pixels) +
                                " pixels with modulation >= " + std::to_string(min_modulation_dn) +
                                " DN (need 1000)");
  auto objective = [&](double gamma) {
    std::vector<detail::PhaseCorrection> tables;
    try {
      const std::vector<float> response = gammaResponse(gamma, 1024);
      for (int j = 0; j < sets; ++j)
        tables.push_back(detail::makePhaseCorrection(response, spec.offset, spec.amplitude,
                                                     set_deltas[j], false, who));
    } catch (const std::invalid_argument&) {
      return std::numeric_limits<double>::infinity();
    }
    double sum = 0;
    for (long x = 0; x < estimate.pixels; ++x) {
      double absolute = tables[0].apply(psi[0][x]);
      for (int j = 1; j < sets; ++j) {
        const double fine = tables[j].apply(psi[j][x]);
        const double cycles = (frequency[j] / frequency[j - 1] * absolute - fine) / kTwoPi;
        const double k = std::round(cycles);
        sum += (cycles - k) * (cycles - k);
        absolute = fine + kTwoPi * k;
      }
    }
    return sum / (static_cast<double>(estimate.pixels) * (sets - 1));
  };
  double best = 1.0, best_value = objective(1.0);
  estimate.rms_residual_linear_periods = std::sqrt(best_value);
  for (double g = 0.3; g <= 4.0 + 1e-9; g += 0.05) {
    const double v = objective(g);
    if (v < best_value) {
      best_value = v;
      best = g;
    }
  }
  // Golden section around the best grid point.
  constexpr double kGolden = 0.6180339887498949;
  double lo = std::max(0.3, best - 0.05), hi = best + 0.05;
  double x1 = hi - kGolden * (hi - lo), x2 = lo + kGolden * (hi - lo);
  double f1 = objective(x1), f2 = objective(x2);
  for (int i = 0; i < 30; ++i) {
    if (f1 < f2) {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - kGolden * (hi - lo);
      f1 = objective(x1);
    } else {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + kGolden * (hi - lo);
      f2 = objective(x2);
    }
  }
  const double refined = 0.5 * (lo + hi);
  const double refined_value = objective(refined);
  if (refined_value < best_value) {
    best = refined;
    best_value = refined_value;
  }
  estimate.gamma = best;
  estimate.rms_residual_periods = std::sqrt(best_value);
  return estimate;
}

}  // namespace sl::pipeline
