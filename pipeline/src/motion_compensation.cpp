#include "sl/pipeline/motion_compensation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "parallel_rows.h"
#include "sl/pipeline/multiversion.h"
#include "sl/pipeline/row_workers.h"

namespace sl::pipeline {

namespace {

// Grid nodes of a lens's undistortion every kGridStep px: the resampling's
// displacement field (the shift through the distortion model) is bilinear
// between them, off the exact field by ~1e-5 px for the sim cameras' lens
// (k1 = -0.08, 12 px of shift: its second derivative is ~6e-7 px per px^2).
// Also the resampling's cell: within one, the source pixels of a row are
// usually the same offset from their destination (the vectorized path).
constexpr int kGridStep = 16;

// Registration averages kAcrossPx full-resolution pixels across the motion
// axis into one line (the subsample factor is along it). The correlation sums
// the cross-power of all lines (below), so averaging neighbouring lines keeps
// what they share, the scene's content of low frequency across the axis, and
// cuts the lines to transform 4x (1440 x 1080 frames moving along y: 180 lines
// of 540 samples, not 720). Fringes across the axis of period p are dimmed by
// sinc(kAcrossPx / p): 0.89 for sim-motion.yaml's ~30 px; they are a nuisance
// to the registration anyway.
constexpr int kAcrossPx = 8;

// Rows of a frame handed to a worker thread at a time by the resampling.
constexpr int kResampleBlockRows = 16;

// Calls fn(begin, end) over blocks of [0, count): on `workers` when given,
// else on OpenCV's threads.
template <typename Fn>
void forBlocks(RowWorkers* workers, int count, int block, const Fn& fn) {
  if (workers) {
    workers->run(count, block, [&](int begin, int end, int) { fn(begin, end); });
  } else {
    parallelRows(count, [&](const cv::Range& r) { fn(r.start, r.end); });
  }
}

// The periodic Hann window 0.5 (1 - cos(2 pi i / n)), i < n (not OpenCV's
// symmetric one, n - 1): its DFT has exactly the frequencies 0 and +-1, so
// whatever does not vary along the motion axis stays in those frequencies of
// the spectrum, which the correlation leaves out.
std::vector<float> periodicHann(int n) {
  std::vector<float> w(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) w[std::size_t(i)] = float(0.5 * (1 - std::cos(2 * CV_PI * i / n)));
  return w;
}

// `image` (CV_8UC1, CV_16UC1 or CV_32FC1) averaged over blocks of fx x fy
// pixels: out(r, c) is the mean of rows r fy .. r fy + fy - 1, columns
// c fx .. c fx + fx - 1 (CV_32FC1, cols / fx x rows / fy; a remainder is left
// out). cv::resize's INTER_AREA does this too, but for unequal factors took
// longer than the whole registration of a frame does here.
//
// Integer pixels are summed in integers (Sum: exact, fx fy <= 64 pixels of
// at most 16 bits), then scaled once: the same result as summing them in
// floats (exact below 2^24).
template <typename T, typename Sum, int kFx>
SL_MULTIVERSION void boxAverageRows(const cv::Mat& image, int fy, int rows, int cols, Sum* __restrict s,
                                    cv::Mat& out) {
  const int width = cols * kFx;
  const float scale = 1.0f / float(kFx * fy);
  for (int r = 0; r < rows; ++r) {
    const T* __restrict first = image.ptr<T>(r * fy);
    for (int c = 0; c < width; ++c) s[c] = Sum(first[c]);
    for (int k = 1; k < fy; ++k) {
      const T* __restrict in = image.ptr<T>(r * fy + k);
      for (int c = 0; c < width; ++c) s[c] += Sum(in[c]);
    }
    float* __restrict o = out.ptr<float>(r);
    for (int c = 0; c < cols; ++c) {
      Sum v = 0;
      for (int k = 0; k < kFx; ++k) v += s[c * kFx + k];
      o[c] = float(v) * scale;
    }
  }
}

template <typename T, typename Sum>
void boxAverageOf(const cv::Mat& image, int fx, int fy, cv::Mat& out) {
  const int cols = image.cols / fx, rows = image.rows / fy;
  out.create(rows, cols, CV_32FC1);
  std::vector<Sum> sum(static_cast<std::size_t>(cols) * static_cast<std::size_t>(fx));
  switch (fx) {
    case 1: boxAverageRows<T, Sum, 1>(image, fy, rows, cols, sum.data(), out); break;
    case 2: boxAverageRows<T, Sum, 2>(image, fy, rows, cols, sum.data(), out); break;
    case 4: boxAverageRows<T, Sum, 4>(image, fy, rows, cols, sum.data(), out); break;
    case 8: boxAverageRows<T, Sum, 8>(image, fy, rows, cols, sum.data(), out); break;
    default: throw std::logic_error("motion compensation: averaging over " + std::to_string(fx) + " px");
  }
}

void boxAverage(const cv::Mat& image, int fx, int fy, cv::Mat& out) {
  if (fx * fy > 64) throw std::logic_error("motion compensation: averaging over more than 64 px");
  switch (image.type()) {
    case CV_8UC1: boxAverageOf<std::uint8_t, std::uint16_t>(image, fx, fy, out); break;
    case CV_16UC1: boxAverageOf<std::uint16_t, std::uint32_t>(image, fx, fy, out); break;
    case CV_32FC1: boxAverageOf<float, float>(image, fx, fy, out); break;
    default: throw std::invalid_argument("motion compensation: frames must be CV_8UC1, CV_16UC1 or CV_32FC1");
  }
}

// Bilinear sample of `src` rows `top`, `bottom` at column c0 (and c0 + 1)
// with weights a (along x) and b (along y), rounded and saturated as
// cv::saturate_cast does (round half to even).
template <typename T>
inline T bilinearAt(const T* top, const T* bottom, int c0, float a, float b) {
  const float upper = float(top[c0]) + a * (float(top[c0 + 1]) - float(top[c0]));
  const float lower = float(bottom[c0]) + a * (float(bottom[c0 + 1]) - float(bottom[c0]));
  const float v = std::nearbyint(upper + b * (lower - upper));
  return T(std::clamp(v, 0.0f, float(std::numeric_limits<T>::max())));
}

// A cell of pixels [begin, begin + n) of a row whose sources all lie
// between the same two pixel pairs, up to resampleRow's margin: columns
// c + dx and c + dx + 1 of source rows r0 and r0 + 1, at weights
// a0 + w sa (along x) and b0 + w sb (along y), w = c - begin. Two contiguous
// source rows, no gathers, so it vectorizes.
struct Cell {
  int begin, n, dx, r0;
  float a0, sa, b0, sb;
};

// kGridStep lanes of floats and of pixels (GCC vector extensions: the
// clones of SL_MULTIVERSION lower them to their own vector width).
typedef float CellFloats __attribute__((vector_size(kGridStep * sizeof(float))));
typedef std::int32_t CellInts __attribute__((vector_size(kGridStep * sizeof(std::int32_t))));
template <typename T>
struct CellPixels;
template <>
struct CellPixels<std::uint8_t> {
  typedef std::uint8_t type __attribute__((vector_size(kGridStep)));
};
template <>
struct CellPixels<std::uint16_t> {
  typedef std::uint16_t type __attribute__((vector_size(kGridStep * 2)));
};

template <typename T>
inline CellFloats loadCell(const T* p) {
  // Widened by a loop (vectorized as one zero extension): GCC lowers
  // __builtin_convertvector from 8-bit lanes lane by lane.
  std::int32_t wide[kGridStep];
  for (int w = 0; w < kGridStep; ++w) wide[w] = p[w];
  CellInts v;
  std::memcpy(&v, wide, sizeof(v));
  return __builtin_convertvector(v, CellFloats);
}

// One full cell: bilinearAt for each of its kGridStep pixels, the same
// operations in the same order. Rounding half to even by adding and
// subtracting 1.5 * 2^23 (exact for |v| < 2^22, the default rounding mode,
// as std::nearbyint), then saturated.
template <typename T>
inline void resampleCell(const T* __restrict top, const T* __restrict bottom, const Cell& cell,
                         T* __restrict out) {
  const CellFloats w = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
  static_assert(kGridStep == 16, "the lane indices above");
  const CellFloats a = cell.a0 + w * cell.sa, b = cell.b0 + w * cell.sb;
  const CellFloats t0 = loadCell(top), t1 = loadCell(top + 1);
  const CellFloats u0 = loadCell(bottom), u1 = loadCell(bottom + 1);
  const CellFloats upper = t0 + a * (t1 - t0);
  const CellFloats lower = u0 + a * (u1 - u0);
  CellFloats v = upper + b * (lower - upper);
  constexpr float kRound = 12582912.0f;  // 1.5 * 2^23
  v = (v + kRound) - kRound;
  const float max = float(std::numeric_limits<T>::max());
  v = v < 0.0f ? CellFloats{} : v;
  v = v > max ? max + CellFloats{} : v;
  const typename CellPixels<T>::type pixels =
      __builtin_convertvector(__builtin_convertvector(v, CellInts), typename CellPixels<T>::type);
  std::memcpy(out, &pixels, sizeof(pixels));
}

template <typename T>
inline void resampleCells(const cv::Mat& frame, const Cell* cells, int count, T* __restrict out) {
  for (int k = 0; k < count; ++k) {
    const Cell& cell = cells[k];
    const T* top = frame.ptr<T>(cell.r0) + cell.begin + cell.dx;
    const T* bottom = frame.ptr<T>(cell.r0 + 1) + cell.begin + cell.dx;
    if (cell.n == kGridStep) {
      resampleCell<T>(top, bottom, cell, out + cell.begin);
    } else {
      for (int w = 0; w < cell.n; ++w)
        out[cell.begin + w] =
            bilinearAt(top, bottom, w, cell.a0 + float(w) * cell.sa, cell.b0 + float(w) * cell.sb);
    }
  }
}

// Row r of `frame` (width x height) resampled into `out`: out[c] = frame at
// (c + dx(c), r + dy(c)), the displacement linear over each kGridStep-pixel
// cell j between displacement[j] and displacement[j + 1] (grid_cols nodes,
// the last at or beyond the last pixel). A pixel whose source lies even
// partly outside the frame is 0 and set in `lack`. `cells`: scratch of at
// least grid_cols cells.
//
// Under motion along one axis nearly every cell's sources are one whole
// offset from their pixels (it changes where the shift crosses a whole
// pixel): such cells are resampled by resampleCells, the others pixel by
// pixel.
template <typename T>
SL_MULTIVERSION void resampleRow(const cv::Mat& frame, int r, const cv::Vec2f* displacement, int grid_cols, Cell* cells,
                 T* __restrict out, std::uint8_t* __restrict lack) {
  const int width = frame.cols, height = frame.rows;
  const float last_x = float(width - 1), last_y = float(height - 1);
  // A cell is resampled as one when its sources lie within kMargin of one
  // whole offset's interval [dx, dx + 1] from their pixels and well inside
  // the frame (given the range of x - c, y and x over it: linear along the
  // cell, so its ends bound it). Within kMargin of a node the cell
  // extrapolates its pair of pixels instead of switching to the next pair:
  // the bilinear surface's value within kMargin px of the position (0.26 DN
  // at most for 8 bit), so a shift of nearly whole pixels still takes it.
  constexpr float kMargin = 1e-3f;
  int count = 0;
  for (int j = 0; j + 1 < grid_cols && j * kGridStep < width; ++j) {
    const int c_begin = j * kGridStep, c_end = std::min(width, c_begin + kGridStep), n = c_end - c_begin;
    const cv::Vec2f d0 = displacement[j];
    const cv::Vec2f slope = (displacement[j + 1] - d0) * (1.0f / kGridStep);
    const float last_w = float(n - 1);
    const float e0 = d0[0], e1 = d0[0] + last_w * slope[0];
    const float y0 = float(r) + d0[1], y1 = float(r) + (d0[1] + last_w * slope[1]);
    const float e_low = std::min(e0, e1), e_high = std::max(e0, e1);
    const float y_low = std::min(y0, y1), y_high = std::max(y0, y1);
    const float x_low = std::min(float(c_begin) + e0, float(c_end - 1) + e1);
    const float x_high = std::max(float(c_begin) + e0, float(c_end - 1) + e1);
    const int dx = int(std::floor(e_low + kMargin)), r0 = int(std::floor(y_low + kMargin));
    if (n >= 2 && e_high <= float(dx) + 1 + kMargin && y_high <= float(r0) + 1 + kMargin && y_low >= kMargin &&
        y_high <= last_y - kMargin && r0 >= 0 && r0 + 1 <= height - 1 && x_low >= kMargin &&
        x_high <= last_x - kMargin && c_begin + dx >= 0 && c_end + dx <= width - 1) {
      // b relative to r0 from the integer part first (r - r0 is exact).
      cells[count++] = Cell{c_begin, n, dx, r0, d0[0] - float(dx), slope[0], float(r - r0) + d0[1], slope[1]};
      continue;
    }
    for (int c = c_begin; c < c_end; ++c) {
      const float w = float(c - c_begin);
      const float x = float(c) + d0[0] + w * slope[0];
      const float y = float(r) + d0[1] + w * slope[1];
      if (!(x >= 0 && y >= 0 && x <= last_x && y <= last_y)) {
        lack[c] = 1;
        out[c] = 0;
        continue;
      }
      const int c0 = std::min(int(x), width - 2), row0 = std::min(int(y), height - 2);
      out[c] = bilinearAt(frame.ptr<T>(row0), frame.ptr<T>(row0 + 1), c0, x - float(c0), y - float(row0));
    }
  }
  resampleCells(frame, cells, count, out);
}

}  // namespace

// A camera's undistortion for the compensation in undistorted coordinates;
// its pinhole image has the model's intrinsics without the distortion.
struct MotionCompensator::Lens {
  PinholeModel model;
  // Registration: each sample (line j across the axis, i along it) of the
  // pinhole registration image, bilinear in the box-averaged (distorted)
  // frame: the top-left source's index in it and the weights along its x and
  // y. The same positions for every frame, so they do not bias the shift
  // between two.
  std::vector<int> source;
  std::vector<float> weight_x, weight_y;
  // Undistorted normalized coordinates of the pixels (j kGridStep, i
  // kGridStep), i < grid_rows, j < grid_cols, row-major (the last node of a
  // row or column at or beyond the last pixel).
  int grid_rows = 0, grid_cols = 0;
  std::vector<Eigen::Vector2d> nodes;

  Lens(const PinholeModel& m, const Registration& grid) : model(m) {
    if (m.width < 2 || m.height < 2 || !(m.fx > 0) || !(m.fy > 0))
      throw std::invalid_argument("motion compensation: a camera model without a size or focal length");
    const int along = grid.along, across = grid.across;
    const int lines = grid.lines, samples = grid.samples;
    // The averaged frame: along_x ? lines x samples : samples x lines.
    const int averaged_cols = grid.along_x ? samples : lines;
    const int averaged_rows = grid.along_x ? lines : samples;
    source.resize(std::size_t(lines) * std::size_t(samples));
    weight_x.resize(source.size());
    weight_y.resize(source.size());
    // Averaged pixel k covers the full-resolution pixels k f .. k f + f - 1.
    const double centre_along = 0.5 * (along - 1), centre_across = 0.5 * (across - 1);
    for (int j = 0; j < lines; ++j)
      for (int i = 0; i < samples; ++i) {
        const double a = i * along + centre_along, c = j * across + centre_across;
        const Eigen::Vector2d pixel = grid.along_x ? Eigen::Vector2d(a, c) : Eigen::Vector2d(c, a);
        const Eigen::Vector2d q = m.normalizedToPixel({(pixel.x() - m.cx) / m.fx, (pixel.y() - m.cy) / m.fy});
        const double fx = grid.along_x ? along : across, fy = grid.along_x ? across : along;
        // Clamped to the averaged frame (its border repeated).
        const float x = float(std::clamp((q.x() - 0.5 * (fx - 1)) / fx, 0.0, double(averaged_cols - 1)));
        const float y = float(std::clamp((q.y() - 0.5 * (fy - 1)) / fy, 0.0, double(averaged_rows - 1)));
        const int c0 = std::min(int(x), averaged_cols - 2), r0 = std::min(int(y), averaged_rows - 2);
        const std::size_t k = std::size_t(j) * std::size_t(samples) + std::size_t(i);
        source[k] = r0 * averaged_cols + c0;
        weight_x[k] = x - float(c0);
        weight_y[k] = y - float(r0);
      }
    grid_cols = (m.width - 1 + kGridStep - 1) / kGridStep + 1;
    grid_rows = (m.height - 1 + kGridStep - 1) / kGridStep + 1;
    nodes.reserve(std::size_t(grid_rows) * std::size_t(grid_cols));
    for (int i = 0; i < grid_rows; ++i)
      for (int j = 0; j < grid_cols; ++j)
        nodes.push_back(m.pixelToNormalized(Eigen::Vector2d(j * kGridStep, i * kGridStep)));
  }

  // The pinhole registration image (lines x samples) of an averaged frame.
  void undistort(const cv::Mat& averaged, int lines, int samples, cv::Mat& out) const {
    out.create(lines, samples, CV_32FC1);
    const float* in = averaged.ptr<float>(0);
    const int step = averaged.cols;
    for (int j = 0; j < lines; ++j) {
      float* o = out.ptr<float>(j);
      const std::size_t row = std::size_t(j) * std::size_t(samples);
      for (int i = 0; i < samples; ++i) {
        const float* p = in + source[row + std::size_t(i)];
        const float a = weight_x[row + std::size_t(i)], b = weight_y[row + std::size_t(i)];
        const float upper = p[0] + a * (p[1] - p[0]);
        const float lower = p[step] + a * (p[step + 1] - p[step]);
        o[i] = upper + b * (lower - upper);
      }
    }
  }

  // The displacement (px) at the grid nodes: from each node's pixel to the
  // model's pixel of its undistorted point moved by `shift` (pinhole px)
  // along the axis.
  std::vector<cv::Vec2f> displacement(bool along_x, double shift) const {
    std::vector<cv::Vec2f> d(nodes.size());
    const Eigen::Vector2d step = along_x ? Eigen::Vector2d(shift / model.fx, 0) : Eigen::Vector2d(0, shift / model.fy);
    for (std::size_t k = 0; k < nodes.size(); ++k) {
      const Eigen::Vector2d v = model.normalizedToPixel(nodes[k] + step) - model.normalizedToPixel(nodes[k]);
      d[k] = cv::Vec2f(float(v.x()), float(v.y()));
    }
    return d;
  }
};

MotionCompensator::Registration MotionCompensator::registration(cv::Size size) const {
  Registration g;
  g.along_x = options_.axis == MotionCompensationOptions::Axis::kX;
  const int along_length = g.along_x ? size.width : size.height;
  const int across_length = g.along_x ? size.height : size.width;
  g.along = options_.subsample;
  // Images too small to average 8 lines into one and keep 8 lines.
  g.across = across_length >= 8 * kAcrossPx ? kAcrossPx : 1;
  g.samples = along_length / g.along;
  g.lines = across_length / g.across;
  if (g.samples < 4 || g.lines < 1)
    throw std::invalid_argument("motion compensation: images of " + std::to_string(size.width) + " x " +
                                std::to_string(size.height) + " px are too small to register");
  return g;
}

MotionCompensator::MotionCompensator(MotionCompensationOptions options,
                                     const std::map<std::string, PinholeModel>& cameras)
    : options_(options) {
  if (options_.subsample != 1 && options_.subsample != 2 && options_.subsample != 4)
    throw std::invalid_argument("motion compensation: subsample must be 1, 2 or 4");
  if (!(options_.max_shift_px > 0))
    throw std::invalid_argument("motion compensation: max_shift_px must be > 0");
  for (const auto& [id, model] : cameras)
    if (model.hasDistortion())
      lenses_.emplace(id, std::make_shared<const Lens>(model, registration({model.width, model.height})));
}

cv::Mat MotionCompensator::spectrum(const cv::Mat& image, const Lens* lens) const {
  const Registration g = registration(image.size());
  cv::Mat averaged, lines;
  boxAverage(image, g.along_x ? g.along : g.across, g.along_x ? g.across : g.along, averaged);
  if (lens)
    lens->undistort(averaged, g.lines, g.samples, lines);
  else if (g.along_x)
    lines = averaged;
  else
    cv::transpose(averaged, lines);
  // The image's mean removed (so the DC term does not dominate the window),
  // then the periodic Hann window along and across the axis.
  const float mean = float(cv::mean(lines)[0]);
  const std::vector<float> along_window =
      options_.window ? periodicHann(g.samples) : std::vector<float>(std::size_t(g.samples), 1.0f);
  const std::vector<float> across_window =
      options_.window ? periodicHann(g.lines) : std::vector<float>(std::size_t(g.lines), 1.0f);
  for (int j = 0; j < g.lines; ++j) {
    float* row = lines.ptr<float>(j);
    const float across = across_window[std::size_t(j)];
    for (int i = 0; i < g.samples; ++i) row[i] = (row[i] - mean) * (across * along_window[std::size_t(i)]);
  }
  // Each line's spectrum along the axis (CCS packed, one row per line).
  cv::Mat transformed;
  cv::dft(lines, transformed, cv::DFT_ROWS);
  return transformed;
}

cv::Mat MotionCompensator::correlate(const cv::Mat& fa, const cv::Mat& fb) const {
  // Eq. 10's cross-power spectrum F_b * conj(F_a), summed over the
  // frequencies across the motion axis: its inverse transform is the
  // correlation on the line of zero shift across the axis. By Parseval
  // across the axis that sum is (up to a constant factor) the sum over the
  // lines of each line's 1-D cross-power spectrum along the axis, which is
  // what is computed here: the transforms across the axis are not needed.
  //
  // Summing before normalising matters: the fringes multiply the scene, and
  // the sidebands they create carry the fringes' phase step with opposite
  // signs at +f and -f, which cancels only in the sum. Frequency 0 (no
  // variation along the motion axis: the fringes themselves) is left out,
  // and with the Hann window also +-1: the (periodic) window's spectrum has
  // exactly the frequencies 0 and +-1, so the static fringes times the window
  // lie there. Kept, they pull the peak away from the true shift: two frames
  // of the same fringes phase-stepped by 2 pi / 3 (3+3's unit-frequency
  // frames) correlate there with the sign of cos(2 pi / 3) < 0, a cosine of
  // one period over the image whose maximum is half an image away, so the
  // peak went to the edge of the search range (measured on sl_eval wall's
  // frames: -201 px and +199 px against a true -4.2 px; -4.24 px without
  // +-1).
  //
  // The sum is then whitened partially (divided by the square root of its
  // magnitude) rather than fully as in eq. 10: with strong fringes, full
  // whitening gives frequencies that hold only leakage the same weight as the
  // scene's and the peak wanders by pixels, while no whitening gives a broad
  // peak. Measured on exactly shifted synthetic fringe images (480 x 360,
  // fringe contrast 0.3-0.8, shifts up to 9 px): max error 0.036 px with the
  // square root, 7-12 px with full whitening (1-D or OpenCV's 2-D
  // phaseCorrelate), up to 229 px without whitening.
  const int lines = fa.rows, n = fa.cols, half = n / 2;
  const int skipped = options_.window ? 1 : 0;  // |frequency| <= skipped left out
  std::vector<double> re(std::size_t(half) + 1, 0.0), im(std::size_t(half) + 1, 0.0);
  // CCS rows: Re0, Re1, Im1, Re2, Im2, ... (and Re(n/2) last for even n).
  const int pairs = (n - 1) / 2;
  for (int j = 0; j < lines; ++j) {
    const float* a = fa.ptr<float>(j);
    const float* b = fb.ptr<float>(j);
    for (int k = 1; k <= pairs; ++k) {
      const float ar = a[2 * k - 1], ai = a[2 * k], br = b[2 * k - 1], bi = b[2 * k];
      re[std::size_t(k)] += double(br * ar + bi * ai);
      im[std::size_t(k)] += double(bi * ar - br * ai);
    }
    if (n % 2 == 0) re[std::size_t(half)] += double(b[n - 1] * a[n - 1]);
  }
  cv::Mat line(1, n, CV_32FC2, cv::Scalar(0, 0));
  auto* out = line.ptr<cv::Vec2f>(0);
  for (int k = skipped + 1; k <= half; ++k) {
    const double magnitude = std::hypot(re[std::size_t(k)], im[std::size_t(k)]);
    if (!(magnitude > 1e-30)) continue;
    const double scale = 1.0 / std::sqrt(magnitude);
    out[k] = cv::Vec2f(float(re[std::size_t(k)] * scale), float(im[std::size_t(k)] * scale));
    out[n - k] = cv::Vec2f(out[k][0], -out[k][1]);  // Hermitian: a real correlation
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


cv::Mat MotionCompensator::resample(const cv::Mat& frame, double shift, const Lens* lens, cv::Mat& lacking,
                                    RowWorkers* workers) const {
  const bool along_x = options_.axis == MotionCompensationOptions::Axis::kX;
  const int width = frame.cols, height = frame.rows;
  // Without a lens the displacement is the shift everywhere (one cell of
  // nodes per row, constant).
  const int grid_cols = lens ? lens->grid_cols : (width - 1 + kGridStep - 1) / kGridStep + 1;
  const int grid_rows = lens ? lens->grid_rows : 2;
  const std::vector<cv::Vec2f> displacement =
      lens ? lens->displacement(along_x, shift)
           : std::vector<cv::Vec2f>(std::size_t(grid_rows) * std::size_t(grid_cols),
                                    along_x ? cv::Vec2f(float(shift), 0) : cv::Vec2f(0, float(shift)));
  cv::Mat out(frame.size(), frame.type());
  const bool wide = frame.depth() == CV_16U;
  forBlocks(workers, height, kResampleBlockRows, [&](int begin, int end) {
    std::vector<cv::Vec2f> row_displacement(static_cast<std::size_t>(grid_cols));
    std::vector<Cell> cells(static_cast<std::size_t>(grid_cols));
    for (int r = begin; r < end; ++r) {
      const int i = lens ? std::min(r / kGridStep, grid_rows - 2) : 0;
      const float t = lens ? float(r - i * kGridStep) / kGridStep : 0.0f;
      const cv::Vec2f* upper = &displacement[std::size_t(i) * std::size_t(grid_cols)];
      const cv::Vec2f* lower = upper + grid_cols;
      for (int j = 0; j < grid_cols; ++j) row_displacement[std::size_t(j)] = upper[j] + t * (lower[j] - upper[j]);
      if (wide)
        resampleRow(frame, r, row_displacement.data(), grid_cols, cells.data(),
                    out.ptr<std::uint16_t>(r), lacking.ptr<std::uint8_t>(r));
      else
        resampleRow(frame, r, row_displacement.data(), grid_cols, cells.data(),
                    out.ptr<std::uint8_t>(r), lacking.ptr<std::uint8_t>(r));
    }
  });
  return out;
}

std::vector<double> expectedShiftsPx(double velocity_mm_s, double focal_px, double depth_mm,
                                     const std::vector<std::int64_t>& stamps_ns) {
  if (!(depth_mm > 0) || !(focal_px > 0))
    throw std::invalid_argument("motion compensation: expected shifts need a depth and focal length > 0");
  std::vector<double> shifts;
  for (const std::int64_t t : stamps_ns)
    shifts.push_back(-velocity_mm_s * double(t - stamps_ns.front()) * 1e-9 * focal_px / depth_mm);
  return shifts;
}

std::shared_ptr<const ImageSet> MotionCompensator::compensate(const ImageSet& set, MotionEstimate* estimate,
                                                              RowWorkers* workers, const MotionPrior* prior) const {
  if (prior && !(prior->tolerance_px > 0))
    throw std::invalid_argument("motion compensation: the prior's tolerance must be > 0");
  if (set.cameras.empty() || set.cameras.front().frames.empty())
    throw std::invalid_argument("motion compensation: empty image set");
  auto out = std::make_shared<ImageSet>(set);  // frames are shared until replaced
  MotionEstimate local;
  MotionEstimate& result = estimate ? *estimate : local;
  result = {};
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
      if (frame.type() != CV_8UC1 && frame.type() != CV_16UC1)
        throw std::invalid_argument("motion compensation: frames must be CV_8UC1 or CV_16UC1");
    }
    const std::vector<double>* expected = nullptr;
    if (prior) {
      const auto listed = prior->expected_shifts_px.find(camera.camera_id);
      if (listed != prior->expected_shifts_px.end()) {
        expected = &listed->second;
        if (static_cast<int>(expected->size()) != n)
          throw std::invalid_argument("motion compensation: the prior for camera '" + camera.camera_id +
                                      "' has " + std::to_string(expected->size()) + " shifts for " +
                                      std::to_string(n) + " frames");
      }
    }
    std::vector<double> shifts(n, 0.0);
    std::vector<bool> within(n, true), corrected(n, false), resampled(n, false);
    // Each frame's spectrum and its correlation with the reference's; one
    // frame per thread.
    std::vector<cv::Mat> spectra(n), correlations(n);
    forBlocks(workers, n, 1, [&](int begin, int end) {
      for (int i = begin; i < end; ++i) spectra[std::size_t(i)] = spectrum(camera.frames[i], lens);
    });
    for (int i = 0; i < n; ++i) {
      if (i == ref) continue;
      correlations[i] = correlate(spectra[std::size_t(ref)], spectra[std::size_t(i)]);
      if (expected) {
        // Relative to the reference, whatever the prior says of the reference.
        const double e = (*expected)[std::size_t(i)] - (*expected)[std::size_t(ref)];
        const double near = peakShiftWithin(correlations[i], e - prior->tolerance_px, e + prior->tolerance_px);
        shifts[i] = std::isnan(near) ? e : near;
        if (std::isnan(near)) ++result.frames_at_prior;
      } else {
        shifts[i] = peakShift(correlations[i]);
      }
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
    // The pixels some frame lacks (their source lies even partly outside the
    // frame).
    cv::Mat lacking = cv::Mat::zeros(camera.frames[ref].size(), CV_8UC1);
    for (int i = 0; i < n; ++i) {
      if (i == ref) continue;
      if (!within[i]) {
        result.all_within_limit = false;
        shifts[i] = 0;
        continue;
      }
      camera.frames[i] = resample(camera.frames[i], shifts[i], lens, lacking, workers);
      resampled[i] = true;
    }
    // Those pixels are 0 in every frame (dimmed or missing in one frame, they
    // would decode to a wrong phase; 0 in all, they have no modulation).
    if (cv::countNonZero(lacking) == 0) {
      if (&camera == &out->cameras.front() && ref < static_cast<int>(camera.stamps_ns.size()))
        out->trigger_stamp_ns = camera.stamps_ns[ref];
      result.shifts_px.push_back(std::move(shifts));
      result.corrected.push_back(std::move(corrected));
      continue;
    }
    for (int i = 0; i < n; ++i)
      if (!resampled[i]) camera.frames[i] = camera.frames[i].clone();  // not the input's pixels
    const bool wide = camera.frames[ref].depth() == CV_16U;
    forBlocks(workers, lacking.rows, kResampleBlockRows, [&](int begin, int end) {
      for (int r = begin; r < end; ++r) {
        const std::uint8_t* lack = lacking.ptr<std::uint8_t>(r);
        const std::uint8_t* lack_end = lack + lacking.cols;
        for (const void* p = std::memchr(lack, 1, lacking.cols); p;
             p = std::memchr(static_cast<const std::uint8_t*>(p) + 1, 1,
                             std::size_t(lack_end - static_cast<const std::uint8_t*>(p) - 1))) {
          const int c = int(static_cast<const std::uint8_t*>(p) - lack);
          for (cv::Mat& frame : camera.frames) {
            if (wide)
              frame.ptr<std::uint16_t>(r)[c] = 0;
            else
              frame.ptr<std::uint8_t>(r)[c] = 0;
          }
        }
      }
    });
    if (&camera == &out->cameras.front() && ref < static_cast<int>(camera.stamps_ns.size()))
      out->trigger_stamp_ns = camera.stamps_ns[ref];
    result.shifts_px.push_back(std::move(shifts));
    result.corrected.push_back(std::move(corrected));
  }
  return out;
}

}  // namespace sl::pipeline
