// Tests of the simulator's optics and electronics beyond the pinhole model:
// projector intensity response (gamma), exposure, gain and saturation. Each
// test compares the rendered images (or what they decode to) with the ground
// truth and an independent model.
#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <vector>

#include "sl/drivers/sim.h"
#include "support/sim_rig.h"

namespace {

using sl::drivers::SimConfig;
using sl::drivers::SimPlane;
using sl::drivers::SimulatedSensor;

constexpr double kPi = std::numbers::pi;
constexpr int kFringes = 16;  // periods across the projector's 1824 columns

// A matte wall at 550 mm, noise off, 16-bit ADC (so quantisation does not
// mask sub-milliradian effects), pinhole optics, one 3+3 column-encoding
// pattern.
SimConfig wallConfig(int fringes = kFringes) {
  SimConfig c = sl::test::simConfig33("3+3", fringes);
  c.scene.planes = {SimPlane{{0, 0, 550}, {0, 0, -1}, 0.8}};
  c.gain_dn_per_electron = 0;
  c.read_noise_dn = 0;
  c.bit_depth = 16;
  c.projector_brightness_dn = 150;
  c.camera_lens.f_number = 0;  // pinhole optics unless a test says otherwise
  c.projector_lens.f_number = 0;
  return c;
}

double wrap(double a) { return std::remainder(a, 2 * kPi); }

// 3-step wrapped phase of intensities shifted by 0, 2 pi / 3, 4 pi / 3
// (I_k = A + B cos(phi - 2 pi k / 3)).
double threeStepPhase(double i0, double i1, double i2) {
  return std::atan2(std::sqrt(3.0) * (i1 - i2), 2 * i0 - i1 - i2);
}

// Amplitude of the 3rd harmonic of a phase error e(phi) sampled at phases
// phi, and the rms left after removing the mean and that harmonic.
struct Ripple {
  double third_harmonic = 0;  // rad
  double residual_rms = 0;    // rad
};
Ripple thirdHarmonic(const std::vector<double>& phi, const std::vector<double>& error) {
  // Least squares on [1, sin 3phi, cos 3phi].
  Eigen::MatrixXd a(static_cast<Eigen::Index>(phi.size()), 3);
  Eigen::VectorXd b(static_cast<Eigen::Index>(phi.size()));
  for (std::size_t i = 0; i < phi.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    a.row(k) << 1.0, std::sin(3 * phi[i]), std::cos(3 * phi[i]);
    b(k) = error[i];
  }
  const Eigen::Vector3d x = a.colPivHouseholderQr().solve(b);
  Ripple r;
  r.third_harmonic = std::hypot(x(1), x(2));
  r.residual_rms = std::sqrt((a * x - b).squaredNorm() / double(phi.size()));
  return r;
}

// Decodes the fine fringes (frames 0..2) of the rendered wall and returns the
// phase error against the ground-truth projector column, per lit pixel
// (every 3rd row and column).
Ripple decodedRipple(const SimulatedSensor& sensor) {
  std::vector<cv::Mat> images;
  for (int f = 0; f < 3; ++f) images.push_back(sensor.render("3+3", f, 0));
  const cv::Mat& up = sensor.groundTruth().up;
  std::vector<double> phi, error;
  for (int r = 0; r < up.rows; r += 3)
    for (int c = 0; c < up.cols; c += 3) {
      const float u = up.at<float>(r, c);
      if (std::isnan(u)) continue;
      const double truth = 2 * kPi * kFringes * u / 1824.0;
      const double measured =
          threeStepPhase(images[0].at<std::uint16_t>(r, c), images[1].at<std::uint16_t>(r, c),
                         images[2].at<std::uint16_t>(r, c));
      phi.push_back(wrap(truth));
      error.push_back(wrap(measured - truth));
    }
  REQUIRE(phi.size() > 10000);
  return thirdHarmonic(phi, error);
}

// The same for the continuous 1-D model: emitted light (0.5 + 0.5 cos)^gamma.
double modelThirdHarmonic(double gamma) {
  std::vector<double> phi, error;
  for (int i = 0; i < 3600; ++i) {
    const double p = wrap(2 * kPi * (i + 0.5) / 3600);
    double light[3];
    for (int k = 0; k < 3; ++k)
      light[k] = std::pow(0.5 + 0.5 * std::cos(p - 2 * kPi * k / 3), gamma);
    phi.push_back(p);
    error.push_back(wrap(threeStepPhase(light[0], light[1], light[2]) - p));
  }
  return thirdHarmonic(phi, error).third_harmonic;
}

}  // namespace

TEST_CASE("projector gamma: 3-step phase error is a 3rd-harmonic ripple of the model's size",
          "[sim][optics][gamma]") {
  SimConfig linear = wallConfig();
  const Ripple flat = decodedRipple(*SimulatedSensor::create(linear));
  SimConfig gamma = wallConfig();
  gamma.projector_gamma = 2.2;
  const Ripple rippled = decodedRipple(*SimulatedSensor::create(gamma));
  const double expected = modelThirdHarmonic(2.2);
  INFO("linear: 3rd harmonic " << flat.third_harmonic << " rad, residual " << flat.residual_rms);
  INFO("gamma 2.2: 3rd harmonic " << rippled.third_harmonic << " rad (model " << expected
                                  << "), residual " << rippled.residual_rms);
  CHECK(expected > 0.05);  // the model itself predicts a visible ripple
  CHECK(rippled.third_harmonic == Approx(expected).epsilon(0.05));
  // The ripple is the error: little is left once the 3rd harmonic is removed.
  CHECK(rippled.residual_rms < 0.2 * rippled.third_harmonic);
  // Linear response: no ripple beyond the 8-bit pattern's rounding.
  CHECK(flat.third_harmonic < 0.02 * expected);
  CHECK(flat.residual_rms < 0.01);
}

TEST_CASE("projector response table: linear table = default, gamma table = gamma",
          "[sim][optics][gamma]") {
  const cv::Mat reference = SimulatedSensor::create(wallConfig())->render("3+3", 1, 0);
  SimConfig table = wallConfig();
  table.projector_response = {0.0, 0.5, 1.0};
  CHECK(cv::norm(SimulatedSensor::create(table)->render("3+3", 1, 0), reference, cv::NORM_INF) ==
        0);

  SimConfig gamma = wallConfig();
  gamma.projector_gamma = 2.2;
  SimConfig sampled = wallConfig();
  for (int k = 0; k <= 255; ++k) sampled.projector_response.push_back(std::pow(k / 255.0, 2.2));
  const cv::Mat a = SimulatedSensor::create(gamma)->render("3+3", 1, 0);
  const cv::Mat b = SimulatedSensor::create(sampled)->render("3+3", 1, 0);
  CHECK(cv::norm(a, b, cv::NORM_INF) <= 1);  // 16-bit DN: float rounding only
  CHECK(cv::norm(a, reference, cv::NORM_INF) > 1000);

  SimConfig bad = wallConfig();
  bad.projector_gamma = 0;
  CHECK_THROWS_WITH(SimulatedSensor::create(bad), Catch::Contains("projector_gamma"));
  bad = wallConfig();
  bad.projector_response = {0.0, 1.5};
  CHECK_THROWS_WITH(SimulatedSensor::create(bad), Catch::Contains("projector_response"));
  bad = wallConfig();
  bad.projector_response = {0.0, 1.0};
  bad.projector_gamma = 2.0;
  CHECK_THROWS_WITH(SimulatedSensor::create(bad), Catch::Contains("projector_gamma"));
}

TEST_CASE("exposure scales signal and ambient; gain scales signal and noise; ADC saturates",
          "[sim][radiometry][exposure]") {
  SimConfig base = wallConfig();
  base.ambient_dn = 20;
  const cv::Rect block(700, 520, 24, 24);
  auto meanOf = [&](const SimConfig& c, int frame) {
    return cv::mean(SimulatedSensor::create(c)->render("3+3", frame, 0)(block))[0];
  };
  const double full_scale = 65535.0;
  const double reference = meanOf(base, 0);
  REQUIRE(reference > 0.1 * full_scale);

  SimConfig longer = base;
  longer.exposure_ms = 2 * base.reference_exposure_ms;
  CHECK(meanOf(longer, 0) == Approx(2 * reference).epsilon(1e-4));
  SimConfig gained = base;
  gained.analog_gain = 1.8;
  CHECK(meanOf(gained, 0) == Approx(1.8 * reference).epsilon(1e-4));
  // Ambient alone (projector off) follows the exposure too.
  SimConfig dark = base;
  dark.projector_brightness_dn = 0;
  SimConfig dark_longer = longer;
  dark_longer.projector_brightness_dn = 0;
  CHECK(meanOf(dark, 0) == Approx(20 * 0.8 * full_scale / 255).epsilon(1e-4));
  CHECK(meanOf(dark_longer, 0) == Approx(2 * meanOf(dark, 0)).epsilon(1e-4));

  // Noise: std^2 = G k S' + (G r)^2 on the 8-bit scale, S' the signal after gain.
  SimConfig noisy = gained;
  noisy.gain_dn_per_electron = 0.1;
  noisy.read_noise_dn = 1.0;
  noisy.bit_depth = 12;
  const auto sensor = SimulatedSensor::create(noisy);
  cv::Mat difference;
  cv::subtract(sensor->render("3+3", 0, 1)(block), sensor->render("3+3", 0, 2)(block), difference,
               cv::noArray(), CV_64F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(difference, mean, stddev);
  const double to_8bit = 255.0 / 4095.0;
  const double signal_8bit = 1.8 * reference * 255.0 / full_scale;
  const double model_std = std::sqrt(1.8 * 0.1 * signal_8bit + 1.8 * 1.8 * 1.0);
  const double measured_std = stddev[0] * to_8bit / std::sqrt(2.0);  // difference of two draws
  INFO("signal " << signal_8bit << " DN, noise std " << measured_std << " (model " << model_std
                 << ")");
  CHECK(measured_std == Approx(model_std).epsilon(0.08));

  // Saturation: the ADC's full scale, exactly.
  SimConfig saturated = base;
  saturated.analog_gain = 8;
  saturated.bit_depth = 10;
  const cv::Mat image = SimulatedSensor::create(saturated)->render("3+3", 0, 0);
  double min_value, max_value;
  cv::minMaxLoc(image, &min_value, &max_value);
  CHECK(max_value == 1023);
  CHECK(cv::countNonZero(image == 1023) > int(image.total() / 10));

  SimConfig bad = base;
  bad.exposure_ms = 40;  // 30 fps: 33 ms frames
  CHECK_THROWS_WITH(SimulatedSensor::create(bad), Catch::Contains("exposure_ms"));
  bad = base;
  bad.analog_gain = 0;
  CHECK_THROWS_WITH(SimulatedSensor::create(bad), Catch::Contains("analog_gain"));
}

namespace {

// 3-step modulation B of the fine fringes (frames 0..2) at (row, col).
double modulationAt(const std::vector<cv::Mat>& images, int row, int col) {
  const double i0 = images[0].at<std::uint16_t>(row, col);
  const double i1 = images[1].at<std::uint16_t>(row, col);
  const double i2 = images[2].at<std::uint16_t>(row, col);
  return std::sqrt(3 * (i1 - i2) * (i1 - i2) + (2 * i0 - i1 - i2) * (2 * i0 - i1 - i2)) / 3;
}

std::vector<cv::Mat> fineFringes(const SimulatedSensor& sensor) {
  std::vector<cv::Mat> images;
  for (int f = 0; f < 3; ++f) images.push_back(sensor.render("3+3", f, 0));
  return images;
}

// The wall with 120 fringes across the projector (period 15.2 projector px).
constexpr int kFineFringes = 120;
SimConfig fineWall() { return wallConfig(kFineFringes); }

struct MtfComparison {
  double mean_measured = 0, mean_expected = 0, max_error = 0;
  int pixels = 0;
};

// Ratio of the blurred to the sharp modulation against the Gaussian MTF
// exp(-2 pi^2 sigma^2 / T^2), per pixel of the image's central region.
template <typename Expected>
MtfComparison compareMtf(const SimulatedSensor& sharp, const SimulatedSensor& blurred,
                         Expected expected) {
  const std::vector<cv::Mat> a = fineFringes(sharp), b = fineFringes(blurred);
  const cv::Mat& lit = sharp.groundTruth().lit;
  MtfComparison m;
  for (int r = 200; r < 880; r += 7)
    for (int c = 300; c < 1140; c += 7) {
      if (!lit.at<std::uint8_t>(r, c)) continue;
      const double reference = modulationAt(a, r, c);
      if (reference < 1000) continue;  // 16-bit DN
      const double measured = modulationAt(b, r, c) / reference;
      const double model = expected(r, c);
      m.mean_measured += measured;
      m.mean_expected += model;
      m.max_error = std::max(m.max_error, std::abs(measured - model));
      ++m.pixels;
    }
  REQUIRE(m.pixels > 5000);
  m.mean_measured /= m.pixels;
  m.mean_expected /= m.pixels;
  return m;
}

}  // namespace

TEST_CASE("projector defocus: fringe modulation falls as the Gaussian MTF of the thin lens",
          "[sim][optics][defocus]") {
  const auto sharp = SimulatedSensor::create(fineWall());
  SimConfig config = fineWall();
  // Focused at 1 m, wide open: the wall at ~0.55 m is blurred by ~2.6 px.
  config.projector_lens = {1000, 2, 5.4};
  const auto blurred = SimulatedSensor::create(config);
  const cv::Mat& xyz = sharp->groundTruth().xyz_mm;
  const double period = 1824.0 / kFineFringes;
  const sl::drivers::SimLens& lens = config.projector_lens;
  const double fx = 0.5 * (config.rig.projector.fx + config.rig.projector.fy);
  double max_sigma = 0;
  const MtfComparison m = compareMtf(*sharp, *blurred, [&](int r, int c) {
    const cv::Vec3f p = xyz.at<cv::Vec3f>(r, c);
    const Eigen::Vector3d in_projector =
        config.rig.R * Eigen::Vector3d(p[0], p[1], p[2]) + config.rig.t;
    const double sigma = lens.blurSigmaPx(in_projector.z(), fx);
    max_sigma = std::max(max_sigma, sigma);
    return std::exp(-2 * kPi * kPi * sigma * sigma / (period * period));
  });
  INFO("pixels " << m.pixels << ", mean modulation ratio " << m.mean_measured << " (model "
                 << m.mean_expected << "), max |error| " << m.max_error << ", sigma up to "
                 << max_sigma << " px");
  CHECK(max_sigma > 2);
  CHECK(m.mean_expected < 0.7);  // a clearly visible loss
  CHECK(m.mean_measured == Approx(m.mean_expected).margin(0.005));
  CHECK(m.max_error < 0.015);
}

TEST_CASE("camera defocus: fringe modulation falls as the Gaussian MTF of the thin lens",
          "[sim][optics][defocus]") {
  const auto sharp = SimulatedSensor::create(fineWall());
  SimConfig config = fineWall();
  config.camera_lens = {1000, 2, 3.45};  // the wall at 0.55 m: ~2 px
  const auto blurred = SimulatedSensor::create(config);
  const cv::Mat& up = sharp->groundTruth().up;
  const cv::Mat& depth = sharp->groundTruth().depth_mm;
  const double period = 1824.0 / kFineFringes;  // projector px
  const double fx = 0.5 * (config.rig.camera.fx + config.rig.camera.fy);
  double max_sigma = 0;
  const MtfComparison m = compareMtf(*sharp, *blurred, [&](int r, int c) {
    const double sigma = config.camera_lens.blurSigmaPx(depth.at<float>(r, c), fx);
    max_sigma = std::max(max_sigma, sigma);
    // The fringe period in the camera image: projector period / |grad up|.
    const double du = 0.5 * (up.at<float>(r, c + 1) - up.at<float>(r, c - 1));
    const double dv = 0.5 * (up.at<float>(r + 1, c) - up.at<float>(r - 1, c));
    const double camera_period = period / std::hypot(du, dv);
    return std::exp(-2 * kPi * kPi * sigma * sigma / (camera_period * camera_period));
  });
  INFO("pixels " << m.pixels << ", mean modulation ratio " << m.mean_measured << " (model "
                 << m.mean_expected << "), max |error| " << m.max_error << ", sigma up to "
                 << max_sigma << " px");
  CHECK(max_sigma > 1.5);
  CHECK(m.mean_expected < 0.85);
  CHECK(m.mean_measured == Approx(m.mean_expected).margin(0.01));
  CHECK(m.max_error < 0.03);
}

TEST_CASE("default lenses: a wall near the focus keeps its modulation; f_number 0 is a pinhole",
          "[sim][optics][defocus]") {
  const auto sharp = SimulatedSensor::create(fineWall());
  SimConfig config = fineWall();
  config.camera_lens = SimConfig{}.camera_lens;
  config.projector_lens = SimConfig{}.projector_lens;
  REQUIRE(config.camera_lens.f_number > 0);
  const auto defaults = SimulatedSensor::create(config);
  const MtfComparison m = compareMtf(*sharp, *defaults, [](int, int) { return 1.0; });
  INFO("mean modulation ratio " << m.mean_measured << ", max |1 - ratio| " << m.max_error);
  CHECK(m.mean_measured > 0.99);
  CHECK(m.max_error < 0.02);

  SimConfig bad = fineWall();
  bad.camera_lens.f_number = -1;
  CHECK_THROWS_WITH(SimulatedSensor::create(bad), Catch::Contains("camera_lens.f_number"));
  bad = fineWall();
  bad.projector_lens = {10, 2, 5.4};  // focus inside twice the focal length (11.9 mm)
  CHECK_THROWS_WITH(SimulatedSensor::create(bad),
                    Catch::Contains("projector_lens.focus_distance_mm"));
}
