// Motion compensation: phase-correlation registration along the motion axis
// against exactly shifted synthetic images. The scene texture is a sum of
// sinusoids (so a sub-pixel shift is exact), lit by fringes that vary across
// the motion axis and stay put in the image, as projected fringes do when the
// whole sensor moves.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include <Eigen/Core>

#include <opencv2/core.hpp>

#include "sl/pipeline/motion_compensation.h"
#include "sl/pipeline/row_workers.h"

using namespace sl::pipeline;

namespace {

struct Texture {
  std::vector<double> fx, fy, phase, amplitude;
  explicit Texture(std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> f(-0.06, 0.06), p(0, 2 * M_PI), a(0.5, 1.0);
    for (int k = 0; k < 24; ++k) {
      fx.push_back(f(rng));
      fy.push_back(f(rng));
      phase.push_back(p(rng));
      amplitude.push_back(a(rng));
    }
  }
  double at(double x, double y) const {
    double v = 0;
    for (std::size_t k = 0; k < fx.size(); ++k)
      v += amplitude[k] * std::cos(2 * M_PI * (fx[k] * x + fy[k] * y) + phase[k]);
    return v;
  }
};

// Frame `i` of a 3-step set: the texture moved by `shift` px along x, lit by
// fringes along y (of `period` px) with phase step i (16-bit, no noise).
cv::Mat frame(const Texture& t, double shift, int i, int width = 480, int height = 360,
             double period = 37.0, double texture = 0.05) {
  cv::Mat image(height, width, CV_16UC1);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const double albedo = 0.5 + texture * t.at(x - shift, y);
      const double fringe = 0.5 + 0.5 * std::cos(2 * M_PI * y / period - 2 * M_PI * i / 3.0);
      image.at<std::uint16_t>(y, x) = cv::saturate_cast<std::uint16_t>(60000 * albedo * (0.2 + 0.8 * fringe));
    }
  return image;
}

}  // namespace

TEST_CASE("phase correlation recovers non-uniform shifts along the motion axis", "[motion]") {
  const int subsample = GENERATE(1, 2);
  const Texture texture(7);
  // Accelerating motion: shifts per image are not evenly spaced.
  const std::vector<double> truth = {0.0, 1.7, 4.1, 7.3, 11.0, 15.6};
  ImageSet set;
  set.cameras.resize(1);
  for (int i = 0; i < 6; ++i) {
    set.cameras[0].frames.push_back(frame(texture, truth[i], i % 3));
    set.cameras[0].stamps_ns.push_back(1000 + i);
  }
  MotionCompensationOptions options;
  options.subsample = subsample;
  const MotionCompensator compensator(options);
  MotionEstimate estimate;
  const auto aligned = compensator.compensate(set, &estimate);
  REQUIRE(estimate.shifts_px.size() == 1);
  const int ref = 3;  // the middle frame
  CHECK(aligned->trigger_stamp_ns == 1000 + ref);
  for (int i = 0; i < 6; ++i) {
    INFO("frame " << i << " subsample " << subsample << ": estimated " << estimate.shifts_px[0][i]
                  << ", true " << truth[i] - truth[ref]);
    CHECK(estimate.shifts_px[0][i] == Approx(truth[i] - truth[ref]).margin(0.15));
  }
  CHECK(estimate.all_within_limit);
  // After compensation every frame registers onto the reference at ~0.
  const MotionCompensator full(MotionCompensationOptions{});
  for (int i = 0; i < 6; ++i) {
    if (i == ref) continue;
    const double residual = full.estimateShift(aligned->cameras[0].frames[ref],
                                               aligned->cameras[0].frames[i]);
    INFO("frame " << i << " residual " << residual);
    CHECK(std::abs(residual) < 0.2);
  }
  // The input set is not modified.
  CHECK(full.estimateShift(set.cameras[0].frames[ref], set.cameras[0].frames[0]) ==
        Approx(truth[0] - truth[ref]).margin(0.2));
}

TEST_CASE("motion along y is registered on transposed images", "[motion]") {
  const Texture texture(11);
  cv::Mat a, b;
  cv::transpose(frame(texture, 0.0, 0), a);
  cv::transpose(frame(texture, 5.4, 1), b);
  MotionCompensationOptions options;
  options.axis = MotionCompensationOptions::Axis::kY;
  CHECK(MotionCompensator(options).estimateShift(a, b) == Approx(5.4).margin(0.15));
}

TEST_CASE("motion compensation rejects bad options and inputs", "[motion]") {
  MotionCompensationOptions options;
  options.subsample = 3;
  CHECK_THROWS_AS(MotionCompensator(options), std::invalid_argument);
  const MotionCompensator ok{MotionCompensationOptions{}};
  CHECK_THROWS_AS(ok.compensate(ImageSet{}), std::invalid_argument);
  CHECK_THROWS_AS(ok.estimateShift(cv::Mat(10, 10, CV_8UC1), cv::Mat(10, 12, CV_8UC1)),
                  std::invalid_argument);
}

// 3+3's unit-frequency frames: one fringe period over the image, a faint
// texture (0.2 % of the albedo). The windowed fringes of two frames
// phase-stepped by 2 pi / 3 correlate negatively at one period per image;
// left in, they pushed the peak to the edge of the search range (here
// +-101 px for -+2.1 px, up to a texture of 0.7 %; sl_eval wall: -201 px
// for -4.2 px), and with OpenCV's symmetric Hann window the static fringes
// leak beyond frequency +-1 (-74 / -70 px at 0.2 %).
TEST_CASE("phase correlation between unit-frequency fringe frames is not pulled by the fringes",
          "[motion]") {
  const Texture texture(11);
  const std::vector<double> truth = {0.0, 2.1, 4.2};
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 3; ++i) frames.push_back(frame(texture, truth[i], i, 480, 360, 420.0, 0.002));
  MotionCompensationOptions options;
  options.subsample = 2;
  options.max_shift_px = 100;
  const MotionCompensator compensator(options);
  for (int i : {0, 2}) {
    const double estimated = compensator.estimateShift(frames[1], frames[i]);
    INFO("frame " << i << ": estimated " << estimated << ", true " << truth[i] - truth[1]);
    CHECK(estimated == Approx(truth[i] - truth[1]).margin(0.15));
  }
}

TEST_CASE("a correlation maximum on the edge of the search range counts as beyond the limit",
          "[motion]") {
  const Texture texture(3);
  MotionCompensationOptions options;
  options.subsample = 1;
  options.max_shift_px = 4;  // the true shift, 9 px, lies beyond
  const MotionCompensator compensator(options);
  const cv::Mat a = frame(texture, 0, 0), b = frame(texture, 9, 0);
  CHECK(std::abs(compensator.estimateShift(a, b)) > options.max_shift_px);
  ImageSet set;
  set.cameras.resize(1);
  set.cameras[0].frames = {a, a, b};
  set.cameras[0].stamps_ns = {1, 2, 3};
  options.reference_frame = 0;
  MotionEstimate estimate;
  MotionCompensator(options).compensate(set, &estimate);
  CHECK_FALSE(estimate.all_within_limit);
  CHECK(estimate.shifts_px[0][2] == 0.0);
}

// Pixels whose source lies partly outside the frame are 0, not a blend of
// the edge pixel with the border (a dimmed pixel decodes to a wrong phase).
TEST_CASE("pixels shifted in from outside the frame are 0, partly outside included", "[motion]") {
  const Texture texture(5);
  for (const double shift : {2.4, -2.4, 3.0}) {
    ImageSet set;
    set.cameras.resize(1);
    set.cameras[0].frames = {frame(texture, 0, 0), frame(texture, shift, 0)};
    set.cameras[0].stamps_ns = {1, 2};
    MotionCompensationOptions options;
    options.reference_frame = 0;
    options.subsample = 1;
    MotionEstimate estimate;
    const auto aligned = MotionCompensator(options).compensate(set, &estimate);
    const cv::Mat& f = aligned->cameras[0].frames[1];
    const cv::Mat& reference = aligned->cameras[0].frames[0];
    const double s = estimate.shifts_px[0][1];
    INFO("shift " << shift << ", estimated " << s);
    REQUIRE(s == Approx(shift).margin(0.1));
    // aligned(x) = frame(x + s): valid where 0 <= x + s <= width - 1.
    for (int x = 0; x < f.cols; ++x) {
      const bool inside = x + s >= 0 && x + s <= f.cols - 1;
      INFO("column " << x);
      // Those pixels are 0 in the reference too (no modulation: invalid).
      if (!inside) CHECK(cv::countNonZero(f.col(x)) == 0);
      if (!inside) CHECK(cv::countNonZero(reference.col(x)) == 0);
      // (the texture itself saturates to 0 in places, so a column need not be all non-zero)
      if (inside && (x + s >= 1 && x + s <= f.cols - 2)) CHECK(cv::countNonZero(f.col(x)) > f.rows / 2);
    }
    // The input's reference frame is not written to.
    CHECK(cv::norm(set.cameras[0].frames[0], frame(texture, 0, 0), cv::NORM_INF) == 0);
  }
}

// A frame whose correlation peaks falsely: its content holds the scene at
// its true place (weaker) and the same scene 50 px further (stronger), so
// that its correlation has a higher maximum far from the true shift, as the
// false peaks seen in sl_eval wall had. Under uniform motion the other frames
// give the speed; the false frame is registered again near the prediction
// and finds the true peak there. Without the check it takes the false one.
TEST_CASE("a frame whose shift disagrees with the sequence's motion is registered near it",
          "[motion]") {
  const Texture texture(13);
  const std::vector<double> truth = {0.0, 2.0, 4.0, 6.0, 8.0, 10.0};
  ImageSet set;
  set.cameras.resize(1);
  for (int i = 0; i < 6; ++i) {
    cv::Mat f = frame(texture, truth[i], i % 3);
    if (i == 5) {
      cv::Mat near, far;
      frame(texture, truth[i], i % 3).convertTo(near, CV_32F);
      frame(texture, truth[i] + 50, i % 3).convertTo(far, CV_32F);
      cv::Mat mixed = 0.35 * near + 0.65 * far;
      mixed.convertTo(f, CV_16U);
    }
    set.cameras[0].frames.push_back(f);
    set.cameras[0].stamps_ns.push_back(1000 + 33'333'333LL * i);
  }
  const int ref = 3;
  MotionCompensationOptions options;
  options.subsample = 1;
  SECTION("checked") {
    MotionEstimate estimate;
    MotionCompensator(options).compensate(set, &estimate);
    INFO("frame 5: " << estimate.shifts_px[0][5] << " px, true " << truth[5] - truth[ref]);
    CHECK(estimate.frames_corrected == 1);
    CHECK(estimate.corrected[0][5]);
    // Near the true peak, not at the false one 50 px away (the two copies
    // modulate the whitening and bias the weaker peak by about a pixel).
    CHECK(estimate.shifts_px[0][5] == Approx(truth[5] - truth[ref]).margin(1.5));
    for (int i = 0; i < 5; ++i) {
      CHECK_FALSE(estimate.corrected[0][i]);
      CHECK(estimate.shifts_px[0][i] == Approx(truth[i] - truth[ref]).margin(0.15));
    }
  }
  SECTION("unchecked") {
    options.max_deviation_px = 0;
    MotionEstimate estimate;
    MotionCompensator(options).compensate(set, &estimate);
    CHECK(estimate.frames_corrected == 0);
    CHECK(estimate.shifts_px[0][5] == Approx(truth[5] + 50 - truth[ref]).margin(0.5));
  }
  SECTION("no peak near the prediction: moved by the prediction") {
    set.cameras[0].frames[5] = frame(texture, truth[5] + 50, 2);
    MotionEstimate estimate;
    MotionCompensator(options).compensate(set, &estimate);
    CHECK(estimate.corrected[0][5]);
    CHECK(estimate.shifts_px[0][5] == Approx(truth[5] - truth[ref]).margin(0.3));
  }
}

// Through a lens model: each pixel of a compensated frame is the frame's
// bilinear value where the model puts its undistorted point moved by the
// estimated shift (computed here in double, per pixel). The vectorized runs
// and the per-pixel path of the resampling agree with it; on the caller's
// RowWorkers the frames are the same as on one thread.
TEST_CASE("frames resampled through a lens are the bilinear values at the model's positions",
          "[motion][lens]") {
  const Texture texture(17);
  PinholeModel model;
  model.width = 480;
  model.height = 360;
  model.fx = model.fy = 800;
  model.cx = 239.5;
  model.cy = 179.5;
  model.distortion = {-0.08, 0.12, 0.0005, -0.0003, 0.0};
  const auto axis = GENERATE(MotionCompensationOptions::Axis::kX, MotionCompensationOptions::Axis::kY);
  const bool along_x = axis == MotionCompensationOptions::Axis::kX;
  ImageSet set;
  set.cameras.resize(1);
  set.cameras[0].camera_id = "lens";
  for (const double shift : {0.0, 3.3, 6.9}) {
    cv::Mat f = frame(texture, shift, 0, 480, 360, 1e9);  // no fringes
    if (!along_x) {
      cv::Mat t = frame(texture, shift, 0, 360, 480, 1e9);
      cv::transpose(t, f);
    }
    set.cameras[0].frames.push_back(f);
    set.cameras[0].stamps_ns.push_back(std::int64_t(set.cameras[0].frames.size()));
  }
  MotionCompensationOptions options;
  options.axis = axis;
  options.reference_frame = 0;
  const MotionCompensator compensator(options, {{"lens", model}});
  MotionEstimate estimate;
  const auto aligned = compensator.compensate(set, &estimate);
  RowWorkers workers(2);
  const auto on_workers = compensator.compensate(set, nullptr, &workers);
  for (int i = 1; i < 3; ++i) {
    const cv::Mat& in = set.cameras[0].frames[i];
    const cv::Mat& out = aligned->cameras[0].frames[i];
    CHECK(cv::norm(out, on_workers->cameras[0].frames[i], cv::NORM_INF) == 0);
    const double shift = estimate.shifts_px[0][i];
    INFO("axis " << (along_x ? "x" : "y") << ", frame " << i << ", shift " << shift);
    CHECK(std::abs(shift) > 2);
    double worst = 0;
    int compared = 0;
    for (int r = 0; r < in.rows; ++r)
      for (int c = 0; c < in.cols; ++c) {
        const Eigen::Vector2d xn = model.pixelToNormalized(Eigen::Vector2d(c, r));
        const Eigen::Vector2d step = along_x ? Eigen::Vector2d(shift / model.fx, 0) : Eigen::Vector2d(0, shift / model.fy);
        const Eigen::Vector2d q = model.normalizedToPixel(xn + step);
        // Away from the frame's edge (the pixels lacking there are 0 in every frame).
        if (!(q.x() >= 1 && q.y() >= 1 && q.x() <= in.cols - 2 && q.y() <= in.rows - 2)) continue;
        const int c0 = int(q.x()), r0 = int(q.y());
        const double a = q.x() - c0, b = q.y() - r0;
        auto at = [&](int y, int x) { return double(in.at<std::uint16_t>(y, x)); };
        const double expected = (1 - b) * ((1 - a) * at(r0, c0) + a * at(r0, c0 + 1)) +
                                b * ((1 - a) * at(r0 + 1, c0) + a * at(r0 + 1, c0 + 1));
        const double got = out.at<std::uint16_t>(r, c);
        if (got == 0) continue;  // lacking in another frame
        worst = std::max(worst, std::abs(got - expected));
        ++compared;
      }
    INFO("compared " << compared << " px, worst " << worst << " DN of 60000");
    CHECK(compared > int(in.total() / 2));
    // Positions within ~1e-3 px (float positions, the displacement
    // interpolated between grid nodes, runs extrapolating within 1e-3 px of
    // a node), the texture's slope at most ~1.3e3 DN per px, plus rounding.
    CHECK(worst <= 4.0);
  }
}

// A repetitive scene: every frame but the reference holds the texture at its
// true place (weaker) and a copy 40 px further (stronger), so every frame's
// correlation peaks falsely, and consistently enough that the check along
// the sequence cannot tell. The sensor's velocity predicts the shifts to
// within a few px: searched within the prior's band around them, every
// frame takes its true peak; unaided, they take the false ones.
TEST_CASE("a prior on the shifts (the sensor's velocity) keeps the true peak of a repetitive scene",
          "[motion][prior]") {
  const Texture texture(19);
  const std::vector<double> truth = {0.0, 2.0, 4.0, 6.0, 8.0, 10.0};
  const int ref = 3;
  ImageSet set;
  set.cameras.resize(1);
  set.cameras[0].camera_id = "top";
  for (int i = 0; i < 6; ++i) {
    cv::Mat f = frame(texture, truth[i], i % 3);
    if (i != ref) {
      cv::Mat near, far;
      f.convertTo(near, CV_32F);
      frame(texture, truth[i] + 40, i % 3).convertTo(far, CV_32F);
      cv::Mat mixed = 0.35 * near + 0.65 * far;
      mixed.convertTo(f, CV_16U);
    }
    set.cameras[0].frames.push_back(f);
    set.cameras[0].stamps_ns.push_back(1000 + 33'333'333LL * i);
  }
  MotionCompensationOptions options;
  options.subsample = 1;
  const MotionCompensator compensator(options);
  // The velocity's prediction: 2.3 px per frame against the true 2.
  MotionPrior prior;
  for (int i = 0; i < 6; ++i) prior.expected_shifts_px["top"].push_back(2.3 * i + 5);
  prior.tolerance_px = 8;

  MotionEstimate unaided, seeded;
  compensator.compensate(set, &unaided);
  compensator.compensate(set, &seeded, nullptr, &prior);
  int unaided_wrong = 0;
  for (int i = 0; i < 6; ++i) {
    const double true_shift = truth[i] - truth[ref];
    INFO("frame " << i << ": unaided " << unaided.shifts_px[0][i] << ", with the prior "
                  << seeded.shifts_px[0][i] << ", true " << true_shift);
    if (std::abs(unaided.shifts_px[0][i] - true_shift) > 10) ++unaided_wrong;
    // The two copies bias the weaker peak by about a pixel (as above).
    CHECK(seeded.shifts_px[0][i] == Approx(true_shift).margin(1.5));
  }
  // The scene does fool the unaided search (else this case tests nothing).
  CHECK(unaided_wrong >= 3);
  CHECK(seeded.frames_at_prior == 0);
  CHECK(seeded.all_within_limit);

  SECTION("no peak near the expected shift: moved by it") {
    MotionPrior far_off = prior;
    for (double& s : far_off.expected_shifts_px["top"]) s *= 12;  // 24 px per frame
    MotionEstimate estimate;
    compensator.compensate(set, &estimate, nullptr, &far_off);
    CHECK(estimate.frames_at_prior >= 1);
    for (int i = 0; i < 6; ++i) {
      const double expected = 12 * (2.3 * i + 5) - 12 * (2.3 * ref + 5);
      const double s = estimate.shifts_px[0][i];
      INFO("frame " << i << ": " << s << ", expected " << expected);
      CHECK(std::abs(s - expected) <= far_off.tolerance_px + 1e-9);
    }
  }
  SECTION("a camera not in the prior is registered unaided; a wrong-sized prior is refused") {
    MotionPrior other;
    other.expected_shifts_px["left"] = prior.expected_shifts_px["top"];
    MotionEstimate estimate;
    compensator.compensate(set, &estimate, nullptr, &other);
    CHECK(estimate.shifts_px == unaided.shifts_px);
    MotionPrior short_list = prior;
    short_list.expected_shifts_px["top"].pop_back();
    CHECK_THROWS_AS(compensator.compensate(set, nullptr, nullptr, &short_list), std::invalid_argument);
    MotionPrior no_tolerance = prior;
    no_tolerance.tolerance_px = 0;
    CHECK_THROWS_AS(compensator.compensate(set, nullptr, nullptr, &no_tolerance), std::invalid_argument);
  }
}

TEST_CASE("expected shifts from the sensor's velocity", "[motion][prior]") {
  // 60 mm/s past a scene at 500 mm, f = 1000 px, 30 fps: 4 px per frame
  // against the motion.
  const std::vector<std::int64_t> stamps = {100, 100 + 33'333'333, 100 + 66'666'667};
  const std::vector<double> shifts = expectedShiftsPx(60, 1000, 500, stamps);
  REQUIRE(shifts.size() == 3);
  CHECK(shifts[0] == 0);
  CHECK(shifts[1] == Approx(-4.0).margin(1e-6));
  CHECK(shifts[2] == Approx(-8.0).margin(1e-6));
  CHECK_THROWS_AS(expectedShiftsPx(60, 1000, 0, stamps), std::invalid_argument);
}
