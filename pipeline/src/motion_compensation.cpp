#include "sl/pipeline/motion_compensation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "parallel_rows.h"

namespace sl::pipeline {

namespace {

// The size cv::resize gives `size` scaled by 1 / factor.
cv::Size subsampledSize(cv::Size size, int factor) {
  return {cvRound(size.width * (1.0 / factor)), cvRound(size.height * (1.0 / factor))};
}

// Grid nodes of a lens's undistortion every kGridStep px: the resampling's
// displacement field (the shift through the distortion model) is bilinear
// between them, off the exact field by ~1e-5 px for the sim cameras' lens
// (k1 = -0.08, 12 px of shift: its second derivative is ~6e-7 px per px^2).
constexpr int kGridStep = 16;

// Bilinear sample of `src` (T: uint8 or uint16) at rows r0, r0 + 1 and
// columns c0, c0 + 1 with weights a (along x) and b (along y), rounded.
template <typename T>
T bilinear(const cv::Mat& src, int r0, int c0, float a, float b) {
  const T* top = src.ptr<T>(r0) + c0;
  const T* bottom = src.ptr<T>(r0 + 1) + c0;
  const float upper = float(top[0]) + a * (float(top[1]) - float(top[0]));
  const float lower = float(bottom[0]) + a * (float(bottom[1]) - float(bottom[0]));
  return cv::saturate_cast<T>(upper + b * (lower - upper));
}

// The periodic Hann window 0.5 (1 - cos(2 pi x / N)) along each axis (not
// OpenCV's symmetric one, N - 1): its DFT has exactly the frequencies 0 and
// +-1, so whatever does not vary along the motion axis stays in those
// columns of the spectrum, which the correlation leaves out.
cv::Mat periodicHann(cv::Size size) {
  auto hann = [](int n) {
    std::vector<float> w(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) w[i] = float(0.5 * (1 - std::cos(2 * CV_PI * i / n)));
    return w;
  };
  const std::vector<float> wx = hann(size.width), wy = hann(size.height);
  cv::Mat window(size, CV_32FC1);
  for (int r = 0; r < size.height; ++r) {
    float* row = window.ptr<float>(r);
    for (int c = 0; c < size.width; ++c) row[c] = wy[r] * wx[c];
  }
  return window;
}

}  // namespace

// A camera's undistortion for the compensation in undistorted coordinates;
// its pinhole image has the model's intrinsics without the distortion.
struct MotionCompensator::Lens {
  PinholeModel model;
  // Registration: for each pixel of the subsampled pinhole image, its
  // position in the subsampled (distorted) frame (cv::remap's maps).
  cv::Mat subsampled_x, subsampled_y;
  // Undistorted normalized coordinates of the pixels (j kGridStep, i
  // kGridStep), i < grid_rows, j < grid_cols, row-major (the last node of a
  // row or column at or beyond the last pixel).
  int grid_rows = 0, grid_cols = 0;
  std::vector<Eigen::Vector2d> nodes;

  Lens(const PinholeModel& m, int factor) : model(m) {
    if (m.width < 2 || m.height < 2 || !(m.fx > 0) || !(m.fy > 0))
      throw std::invalid_argument("motion compensation: a camera model without a size or focal length");
    const cv::Size sub = subsampledSize({m.width, m.height}, factor);
    subsampled_x.create(sub, CV_32FC1);
    subsampled_y.create(sub, CV_32FC1);
    // Subsampled pixel i averages the full-resolution pixels i f .. i f + f - 1.
    const double centre = 0.5 * (factor - 1);
    for (int r = 0; r < sub.height; ++r)
      for (int c = 0; c < sub.width; ++c) {
        const Eigen::Vector2d xn(((c * factor + centre) - m.cx) / m.fx, ((r * factor + centre) - m.cy) / m.fy);
        const Eigen::Vector2d q = m.normalizedToPixel(xn);
        subsampled_x.at<float>(r, c) = float((q.x() - centre) / factor);
        subsampled_y.at<float>(r, c) = float((q.y() - centre) / factor);
      }
    grid_cols = (m.width - 1 + kGridStep - 1) / kGridStep + 1;
    grid_rows = (m.height - 1 + kGridStep - 1) / kGridStep + 1;
    nodes.reserve(std::size_t(grid_rows) * std::size_t(grid_cols));
    for (int i = 0; i < grid_rows; ++i)
      for (int j = 0; j < grid_cols; ++j)
        nodes.push_back(m.pixelToNormalized(Eigen::Vector2d(j * kGridStep, i * kGridStep)));
  }

  // `frame` resampled so that each pixel shows what it showed in the
  // reference frame: from the model's pixel of its undistorted point moved
  // by `shift` (pinhole px) along the axis, bilinear in floating point (not
  // cv::remap, whose positions are fixed-point, 1/32 px: as large as the
  // displacement across the axis this corrects). Pixels whose source lies
  // even partly outside the frame are 0 and set in `lacking` (CV_8UC1).
  cv::Mat resample(const cv::Mat& frame, bool along_x, double shift, cv::Mat& lacking) const {
    const int width = frame.cols, height = frame.rows;
    // The displacement (px) at the grid nodes.
    std::vector<cv::Vec2f> displacement(nodes.size());
    const Eigen::Vector2d step = along_x ? Eigen::Vector2d(shift / model.fx, 0) : Eigen::Vector2d(0, shift / model.fy);
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      const Eigen::Vector2d d = model.normalizedToPixel(nodes[k] + step) - model.normalizedToPixel(nodes[k]);
      displacement[k] = cv::Vec2f(float(d.x()), float(d.y()));
    }
    cv::Mat out(frame.size(), frame.type());
    const bool wide = frame.depth() == CV_16U;
    parallelRows(height, [&](const cv::Range& rows) {
      std::vector<cv::Vec2f> row_displacement(static_cast<std::size_t>(grid_cols));
      for (int r = rows.start; r < rows.end; ++r) {
        const int i = std::min(r / kGridStep, grid_rows - 2);
        const float t = float(r - i * kGridStep) / kGridStep;
        const cv::Vec2f* upper = &displacement[std::size_t(i) * std::size_t(grid_cols)];
        const cv::Vec2f* lower = upper + grid_cols;
        for (int j = 0; j < grid_cols; ++j) row_displacement[std::size_t(j)] = upper[j] + t * (lower[j] - upper[j]);
        std::uint8_t* lack = lacking.ptr<std::uint8_t>(r);
        auto* out8 = out.ptr<std::uint8_t>(r);
        auto* out16 = out.ptr<std::uint16_t>(r);
        for (int j = 0; j + 1 < grid_cols; ++j) {
          const cv::Vec2f d0 = row_displacement[std::size_t(j)];
          const cv::Vec2f slope = (row_displacement[std::size_t(j) + 1] - d0) * (1.0f / kGridStep);
          const int c_end = std::min(width, (j + 1) * kGridStep);
          for (int c = j * kGridStep; c < c_end; ++c) {
            const float w = float(c - j * kGridStep);
            const float x = float(c) + d0[0] + w * slope[0];
            const float y = float(r) + d0[1] + w * slope[1];
            if (!(x >= 0 && y >= 0 && x <= float(width - 1) && y <= float(height - 1))) {
              lack[c] = 1;
              if (wide) out16[c] = 0; else out8[c] = 0;
              continue;
            }
            const int c0 = std::min(int(x), width - 2), r0 = std::min(int(y), height - 2);
            const float a = x - float(c0), b = y - float(r0);
            if (wide)
              out16[c] = bilinear<std::uint16_t>(frame, r0, c0, a, b);
            else
              out8[c] = bilinear<std::uint8_t>(frame, r0, c0, a, b);
          }
        }
      }
    });
    return out;
  }
};

MotionCompensator::MotionCompensator(MotionCompensationOptions options,
                                     const std::map<std::string, PinholeModel>& cameras)
    : options_(options) {
  if (options_.subsample != 1 && options_.subsample != 2 && options_.subsample != 4)
    throw std::invalid_argument("motion compensation: subsample must be 1, 2 or 4");
  if (!(options_.max_shift_px > 0))
    throw std::invalid_argument("motion compensation: max_shift_px must be > 0");
  for (const auto& [id, model] : cameras)
    if (model.hasDistortion()) lenses_.emplace(id, std::make_shared<const Lens>(model, options_.subsample));
}

cv::Mat MotionCompensator::spectrum(const cv::Mat& image, const Lens* lens) const {
  const int factor = options_.subsample;
  cv::Mat f;
  image.convertTo(f, CV_32F);
  if (factor > 1) cv::resize(f, f, cv::Size(), 1.0 / factor, 1.0 / factor, cv::INTER_AREA);
  if (lens) {
    // The pinhole image (cv::remap's 1/32 px positions: the same for every
    // frame, so they do not bias the shift between two).
    cv::Mat pinhole;
    cv::remap(f, pinhole, lens->subsampled_x, lens->subsampled_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    f = pinhole;
  }
  // The motion axis along the columns (x).
  if (options_.axis == MotionCompensationOptions::Axis::kY) cv::transpose(f, f);
  // Remove the image's mean so the DC term does not dominate the window.
  f -= cv::mean(f);
  if (options_.window) {
    if (window_.size() != f.size()) window_ = periodicHann(f.size());
    f = f.mul(window_);
  }
  cv::Mat transformed;
  cv::dft(f, transformed, cv::DFT_COMPLEX_OUTPUT);
  return transformed;
}

cv::Mat MotionCompensator::correlate(const cv::Mat& fa, const cv::Mat& fb) const {
  cv::Mat cross;
  // Eq. 10: C = F_b * conj(F_a) / |F_b * conj(F_a)|; its inverse transform
  // peaks at the shift of b relative to a.
  cv::mulSpectrums(fb, fa, cross, 0, /*conjB=*/true);
  const int rows = cross.rows, cols = cross.cols;
  // Sum the cross-power over the frequencies across the motion axis (rows):
  // its inverse transform is the correlation on the line of zero shift across
  // the axis. Summing before normalising matters: the fringes multiply the
  // scene, and the sidebands they create carry the fringes' phase step with
  // opposite signs at +f and -f, which cancels only in the sum. Column 0 (no
  // variation along the motion axis: the fringes themselves) is left out,
  // and with the Hann window also columns +-1: the (periodic) window's
  // spectrum has exactly the frequencies 0 and +-1, so the static fringes
  // times the window lie there. Kept, they pull the peak away from the true shift: two frames
  // of the same fringes phase-stepped by 2 pi / 3 (3+3's unit-frequency
  // frames) correlate there with the sign of cos(2 pi / 3) < 0, a cosine of
  // one period over the image whose maximum is half an image away, so the
  // peak went to the edge of the search range (measured on sl_eval wall's
  // frames: -201 px and +199 px against a true -4.2 px; -4.24 px without
  // columns +-1).
  //
  // The sum is then whitened partially (divided by the square root of its
  // magnitude) rather than fully as in eq. 10: with strong fringes, full
  // whitening gives frequencies that hold only leakage the same weight as the
  // scene's and the peak wanders by pixels, while no whitening gives a broad
  // peak. Measured on exactly shifted synthetic fringe images (480 x 360,
  // fringe contrast 0.3-0.8, shifts up to 9 px): max error 0.036 px with the
  // square root, 7-12 px with full whitening (1-D or OpenCV's 2-D
  // phaseCorrelate), up to 229 px without whitening.
  const int skipped = options_.window ? 1 : 0;  // |frequency| <= skipped left out
  auto used = [&](int c) { return std::min(c, cols - c) > skipped; };
  std::vector<cv::Vec2d> sum(cols, cv::Vec2d(0, 0));
  for (int r = 0; r < rows; ++r) {
    const auto* in = cross.ptr<cv::Vec2f>(r);
    for (int c = 1; c < cols; ++c)
      if (used(c)) sum[c] += cv::Vec2d(in[c][0], in[c][1]);
  }
  cv::Mat line(1, cols, CV_32FC2, cv::Scalar(0, 0));
  auto* out = line.ptr<cv::Vec2f>(0);
  for (int c = 1; c < cols; ++c) {
    if (!used(c)) continue;
    const double magnitude = std::hypot(sum[c][0], sum[c][1]);
    if (magnitude > 1e-30) {
      const double scale = 1.0 / std::sqrt(magnitude);
      out[c] = cv::Vec2f(float(sum[c][0] * scale), float(sum[c][1] * scale));
    }
  }
  cv::Mat correlation;
  cv::idft(line, correlation, cv::DFT_REAL_OUTPUT | cv::DFT_SCALE);
  return correlation;
}

namespace {

// The correlation's maximum over the shifts [first, last] (subsampled px,
// first <= last, the line circular), refined to sub-pixel by a parabola
// through it and its neighbours. A maximum on an end of the range is no peak
// (the correlation may still rise beyond it): `edge` is then -1 or +1 (the
// end) and the shift NaN; unless the range covers the whole line.
struct Peak {
  double shift = std::numeric_limits<double>::quiet_NaN();
  int edge = 0;
  float value = 0;  // the correlation at the maximum
};

Peak peakWithin(const cv::Mat& correlation, int first, int last) {
  const auto* c = correlation.ptr<float>(0);
  const int cols = correlation.cols;
  auto at = [&](int d) { return c[((d % cols) + cols) % cols]; };
  int best = first;
  for (int d = first; d <= last; ++d)
    if (at(d) > at(best)) best = d;
  Peak peak;
  peak.value = at(best);
  if (last - first + 1 < cols && (best == first || best == last)) {
    peak.edge = best == first ? -1 : 1;
    return peak;
  }
  const float left = at(best - 1), right = at(best + 1), centre = at(best);
  const float denominator = left - 2 * centre + right;
  double offset = denominator != 0 ? 0.5 * (left - right) / denominator : 0.0;
  offset = std::clamp(offset, -0.5, 0.5);
  peak.shift = best + offset;
  return peak;
}

// A re-registration's peak near the prediction must reach this fraction of
// the correlation's maximum (the true peak of a frame with a false one
// elsewhere: about half of it in test_motion_compensation; a side lobe of a
// textured scene's peak: a few tenths at most).
constexpr double kMinPeakRatio = 0.3;

}  // namespace

namespace {

void requireSameSize(const cv::Mat& reference, const cv::Mat& moving) {
  if (reference.size() != moving.size() || reference.empty())
    throw std::invalid_argument("motion compensation: images differ in size or are empty");
}

}  // namespace

double MotionCompensator::estimateShift(const cv::Mat& reference, const cv::Mat& moving) const {
  requireSameSize(reference, moving);
  return peakShift(correlate(spectrum(reference, nullptr), spectrum(moving, nullptr)));
}

double MotionCompensator::estimateShiftWithin(const cv::Mat& reference, const cv::Mat& moving,
                                              double from_px, double to_px) const {
  requireSameSize(reference, moving);
  return peakShiftWithin(correlate(spectrum(reference, nullptr), spectrum(moving, nullptr)), from_px,
                         to_px);
}

double MotionCompensator::peakShift(const cv::Mat& correlation) const {
  const int cols = correlation.cols, factor = options_.subsample;
  // The peak is searched only within +-max_shift_px: a far-away false peak
  // (measured with the Hann window on unit-frequency frames: +620 px against a
  // true -9.3 px) cannot win. A maximum on the edge of the search range is
  // reported as beyond the limit.
  const int reach = std::min(cols / 2, static_cast<int>(std::ceil(options_.max_shift_px / factor)));
  const int last = 2 * reach + 1 > cols ? cols - 1 - reach : reach;  // each shift once
  const Peak peak = peakWithin(correlation, -reach, last);
  if (peak.edge != 0) return peak.edge * (options_.max_shift_px + factor);
  return peak.shift * factor;
}

double MotionCompensator::peakShiftWithin(const cv::Mat& correlation, double from_px,
                                          double to_px) const {
  const int factor = options_.subsample;
  const int first = static_cast<int>(std::ceil(from_px / factor));
  const int last = std::max(first, static_cast<int>(std::floor(to_px / factor)));
  const Peak peak = peakWithin(correlation, first, last);
  // A side lobe of a peak elsewhere is no peak: the maximum in the band must
  // reach kMinPeakRatio of the correlation's global maximum.
  double global = 0;
  cv::minMaxLoc(correlation, nullptr, &global);
  if (!(peak.value >= kMinPeakRatio * global)) return std::numeric_limits<double>::quiet_NaN();
  return peak.shift * factor;
}

std::shared_ptr<const ImageSet> MotionCompensator::compensate(const ImageSet& set,
                                                              MotionEstimate* estimate) const {
  if (set.cameras.empty() || set.cameras.front().frames.empty())
    throw std::invalid_argument("motion compensation: empty image set");
  auto out = std::make_shared<ImageSet>(set);  // frames are shared until replaced
  MotionEstimate local;
  MotionEstimate& result = estimate ? *estimate : local;
  result = {};
  const bool along_x = options_.axis == MotionCompensationOptions::Axis::kX;
  for (CameraImages& camera : out->cameras) {
    const int n = static_cast<int>(camera.frames.size());
    const int ref = options_.reference_frame < 0 ? n / 2 : options_.reference_frame;
    if (ref >= n)
      throw std::invalid_argument("motion compensation: reference frame " + std::to_string(ref) +
                                  " but the sequence has " + std::to_string(n) + " frames");
    const auto lens_of = lenses_.find(camera.camera_id);
    const Lens* lens = lens_of == lenses_.end() ? nullptr : lens_of->second.get();
    for (const cv::Mat& frame : camera.frames) {
      requireSameSize(camera.frames[ref], frame);
      if (lens && (frame.cols != lens->model.width || frame.rows != lens->model.height))
        throw std::invalid_argument("motion compensation: camera '" + camera.camera_id + "' frames are " +
                                    std::to_string(frame.cols) + " x " + std::to_string(frame.rows) +
                                    " px, its model " + std::to_string(lens->model.width) + " x " +
                                    std::to_string(lens->model.height));
      if (lens && frame.type() != CV_8UC1 && frame.type() != CV_16UC1)
        throw std::invalid_argument("motion compensation: frames must be CV_8UC1 or CV_16UC1");
    }
    std::vector<double> shifts(n, 0.0);
    std::vector<bool> within(n, true), corrected(n, false), resampled(n, false);
    std::vector<cv::Mat> correlations(n);
    const cv::Mat reference_spectrum = spectrum(camera.frames[ref], lens);
    for (int i = 0; i < n; ++i) {
      if (i == ref) continue;
      correlations[i] = correlate(reference_spectrum, spectrum(camera.frames[i], lens));
      shifts[i] = peakShift(correlations[i]);
      within[i] = std::abs(shifts[i]) <= options_.max_shift_px;
    }
    // Consistency along the sequence (see the options): the speed is the
    // median over the frames, so that one or two false peaks do not move it.
    const bool stamped = static_cast<int>(camera.stamps_ns.size()) == n;
    auto time = [&](int i) {
      return stamped ? double(camera.stamps_ns[i] - camera.stamps_ns[ref]) : double(i - ref);
    };
    std::vector<double> rates;
    for (int i = 0; i < n; ++i)
      if (i != ref && within[i] && time(i) != 0) rates.push_back(shifts[i] / time(i));
    if (options_.max_deviation_px > 0 && rates.size() >= 3) {
      std::nth_element(rates.begin(), rates.begin() + rates.size() / 2, rates.end());
      double rate = rates[rates.size() / 2];
      if (rates.size() % 2 == 0) {
        const double below = *std::max_element(rates.begin(), rates.begin() + rates.size() / 2);
        rate = 0.5 * (rate + below);
      }
      for (int i = 0; i < n; ++i) {
        if (i == ref) continue;
        const double predicted = rate * time(i);
        const double band =
            std::max(options_.max_deviation_px, options_.max_deviation_fraction * std::abs(predicted));
        if (within[i] && std::abs(shifts[i] - predicted) <= band) continue;
        const double again = peakShiftWithin(correlations[i], predicted - band, predicted + band);
        shifts[i] = std::isnan(again) ? predicted : again;
        within[i] = std::abs(shifts[i]) <= options_.max_shift_px;
        corrected[i] = true;
        ++result.frames_corrected;
      }
    }
    // [from, to) along the axis: the pixels some frame lacks (its source lies
    // even partly outside the frame).
    const int length = along_x ? camera.frames[ref].cols : camera.frames[ref].rows;
    int lacking_before = 0, lacking_from = length;
    cv::Mat lacking;  // through the lens: pixels some frame lacks
    if (lens) lacking = cv::Mat::zeros(camera.frames[ref].size(), CV_8UC1);
    for (int i = 0; i < n; ++i) {
      if (i == ref) continue;
      if (!within[i]) {
        result.all_within_limit = false;
        shifts[i] = 0;
        continue;
      }
      const double shift = shifts[i];
      if (lens) {
        camera.frames[i] = lens->resample(camera.frames[i], along_x, shift, lacking);
        resampled[i] = true;
        continue;
      }
      // Move frame i's content back onto the reference: translate by -shift.
      cv::Mat m = cv::Mat::zeros(2, 3, CV_64F);
      m.at<double>(0, 0) = m.at<double>(1, 1) = 1;
      (along_x ? m.at<double>(0, 2) : m.at<double>(1, 2)) = -shift;
      cv::Mat aligned;
      cv::warpAffine(camera.frames[i], aligned, m, camera.frames[i].size(), cv::INTER_LINEAR,
                     cv::BORDER_CONSTANT, cv::Scalar(0));
      camera.frames[i] = aligned;
      resampled[i] = true;
      // aligned(x) = frame(x + shift): a bilinear blend with the border where
      // x + shift < 0 or > length - 1.
      if (shift < 0)
        lacking_before = std::max(lacking_before, std::min(length, int(std::ceil(-shift))));
      else if (shift > 0)
        lacking_from = std::min(lacking_from, std::max(0, int(std::floor(length - 1 - shift)) + 1));
    }
    // Those pixels are 0 in every frame (dimmed or missing in one frame, they
    // would decode to a wrong phase; 0 in all, they have no modulation).
    if (lens && cv::countNonZero(lacking) > 0) {
      for (int i = 0; i < n; ++i) {
        if (!resampled[i]) camera.frames[i] = camera.frames[i].clone();  // not the input's pixels
        camera.frames[i].setTo(cv::Scalar(0), lacking);
      }
    }
    for (int i = 0; i < n && !lens && (lacking_before > 0 || lacking_from < length); ++i) {
      if (!resampled[i]) camera.frames[i] = camera.frames[i].clone();  // not the input's pixels
      for (const auto& [from, to] : {std::pair{0, lacking_before}, std::pair{lacking_from, length}}) {
        if (to <= from) continue;
        if (along_x)
          camera.frames[i].colRange(from, to).setTo(cv::Scalar(0));
        else
          camera.frames[i].rowRange(from, to).setTo(cv::Scalar(0));
      }
    }
    if (&camera == &out->cameras.front() && ref < static_cast<int>(camera.stamps_ns.size()))
      out->trigger_stamp_ns = camera.stamps_ns[ref];
    result.shifts_px.push_back(std::move(shifts));
    result.corrected.push_back(std::move(corrected));
  }
  return out;
}

}  // namespace sl::pipeline
