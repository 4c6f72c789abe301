// sl_eval's experiments with few scans and the thresholds: precision
// at the phase-noise floor, motion compensation removing the motion ripple
// (uniform and accelerating motion), cone distances from both cameras,
// roughness samples ranked and measured, the VDI/VDE 2634 style test within
// the noise model's bounds, systematic errors < 0.02 mm with a linear
// projector and the error a projector gamma adds. Each runs in seconds (Release).
#include <catch2/catch.hpp>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "eval.h"

namespace {

sl::eval::EvalOptions options(int scans) {
  sl::eval::EvalOptions o;
  o.scans = scans;
  o.out_dir = std::string(SL_BINARY_DIR) + "/test_eval_plots";
  return o;
}

}  // namespace

TEST_CASE("precision: depth noise on a wall at 500 mm is at the phase-noise floor", "[eval]") {
  const sl::eval::EvalResult r = sl::eval::runPrecision(options(4));
  INFO(r.markdown);
  const auto& m = r.metrics;
  CHECK(m.at("valid_fraction") > 0.95);
  // Issue 3: within 1.25x of the theoretical floor (RMS over pixels: unbiased
  // with few scans, unlike the mean of per-pixel standard deviations).
  CHECK(m.at("ratio_rms") < 1.25);
  CHECK(m.at("ratio_rms") > 0.8);
  CHECK(m.at("std_mean_mm") > 0.0);
  // Issue 3: no worse than the paper's SL Sensor (mean 0.070 mm).
  CHECK(m.at("std_mean_mm") <= 0.070);
  // Issue 3: systematic error (mean deviation from the truth) < 0.02 mm.
  CHECK(std::abs(m.at("systematic_mean_mm")) < 0.02);
  CHECK(m.at("period_error_fraction") == 0);
  REQUIRE(r.plots.size() == 1);
  CHECK(std::filesystem::file_size(r.plots[0]) > 1000);
}

TEST_CASE(
    "motion: 2 mm per image (uniform or accelerating) ripples the relief; compensation "
    "removes the ripple",
    "[eval]") {
  const sl::eval::EvalResult r = sl::eval::runMotion(options(2));
  INFO(r.markdown);
  const auto& m = r.metrics;
  // Motion artefacts arise from the frame timing alone.
  CHECK(m.at("static_relief_rms_mm") < 0.3);
  CHECK(m.at("moving_relief_rms_mm") > 1.0);
  CHECK(m.at("moving_ripple_mm") > 1.0);
  // Issue 7's targets: ripple down >= 5x and compensated RMS depth error
  // < 0.1 mm on the relief, also when the sensor accelerates (1 -> 3 mm per
  // image, one pose per image).
  CHECK(m.at("ripple_reduction") >= 5.0);
  CHECK(m.at("ripple_reduction_no_window") >= 5.0);
  CHECK(m.at("compensated_no_window_relief_rms_mm") < 0.1);
  CHECK(m.at("compensated_no_window_systematic_rms_mm") < 0.15);
  CHECK(m.at("compensated_relief_rms_mm") < 0.1);
  CHECK(m.at("accelerating_relief_rms_mm") > 1.0);
  CHECK(m.at("accelerating_ripple_mm") > 1.0);
  CHECK(m.at("accelerating_ripple_reduction") >= 5.0);
  CHECK(m.at("accelerating_compensated_relief_rms_mm") < 0.1);
  // Every registration found its peak within max_shift_px.
  CHECK(m.at("scans_with_rejected_estimate") == 0);
  REQUIRE(r.plots.size() == 2);
  for (const std::string& plot : r.plots) CHECK(std::filesystem::file_size(plot) > 1000);
}

TEST_CASE("unknown experiment names are rejected", "[eval]") {
  CHECK_THROWS_AS(sl::eval::runExperiment("nope", options(1)), std::invalid_argument);
}

TEST_CASE("cones: apex distances from both cameras match the truth", "[eval]") {
  const sl::eval::EvalResult r = sl::eval::runCones(options(2));
  INFO(r.markdown);
  // Perfect calibration: only noise remains (the paper's 0.08..1.1 mm come
  // from the real calibration).
  CHECK(r.metrics.at("worst_rmse_mm") < 0.2);
  // Issue 3: every distance RMSE < 0.1 mm for the top camera.
  for (int k = 2; k <= 6; ++k) CHECK(r.metrics.at("top_rmse_1_" + std::to_string(k) + "_mm") < 0.1);
  CHECK(r.metrics.count("left_rmse_1_6_mm") == 1);
  // Issue 3: systematic errors (mean deviations from the truth) < 0.02 mm.
  for (const char* camera : {"top", "left"}) {
    CHECK(std::abs(r.metrics.at(std::string(camera) + "_distance_mean_error_mm")) < 0.02);
    CHECK(std::abs(r.metrics.at(std::string(camera) + "_surface_mean_deviation_mm")) < 0.02);
  }
}

TEST_CASE("roughness: the samples have the issue's ESDs and the sensor ranks and measures them",
          "[eval]") {
  const sl::eval::EvalResult r = sl::eval::runRoughness(options(4));
  INFO(r.markdown);
  const auto& m = r.metrics;
  const std::vector<std::pair<std::string, double>> truth = {
      {"S1", 0.008}, {"S2", 0.026}, {"S3", 0.053}, {"S4", 0.146}};
  for (const auto& [sample, esd] : truth) {
    // The surface's ESD on the patch is the value; the camera's pixels
    // sample the same surface.
    CHECK(m.at(sample + "_esd_truth_mm") == Approx(esd).epsilon(1e-3));
    CHECK(m.at(sample + "_esd_truth_pixels_mm") == Approx(esd).epsilon(0.03));
    // Noise only adds: a single scan never reads smoother than the truth.
    CHECK(m.at(sample + "_esd_mm") > m.at(sample + "_esd_truth_mm"));
  }
  CHECK(m.at("ranked_correctly") == 1);
  CHECK(m.at("ranked_correctly_averaged") == 1);
  // Issue 3: S3 and S4 within 0.02 mm of the truth. Single scans reach it for
  // S4 only (S3: sqrt(0.053^2 + noise^2) with ~0.058 mm of noise); the mean
  // of the scans (noise / sqrt(4) here) for both.
  CHECK(std::abs(m.at("S4_esd_error_mm")) < 0.02);
  CHECK(std::abs(m.at("S3_esd_averaged_error_mm")) < 0.02);
  CHECK(std::abs(m.at("S4_esd_averaged_error_mm")) < 0.02);
}

TEST_CASE("vdi2634: probing, spacing and flatness errors are those of the camera noise", "[eval]") {
  const sl::eval::EvalResult r = sl::eval::runVdi2634(options(1));
  INFO(r.markdown);
  const auto& m = r.metrics;
  // Form: the range of the residuals (0.3 % discarded, as the guideline
  // allows) within 1.25x of the range that independent Gaussian residuals
  // with each point's noise-model sigma give; the noise model predicts the
  // residuals' RMS too. Period errors of the unwrapping are rare (< 0.1 %)
  // and absent on the planes.
  CHECK(m.at("sphere_form997_ratio_max") < 1.25);
  CHECK(m.at("flatness997_ratio_max") < 1.25);
  CHECK(m.at("flatness_ratio_max") < 1.25);
  CHECK(m.at("sphere_gross_fraction") < 1e-3);
  CHECK(m.at("plane_gross_points") == 0);
  // Size and spacing: each measurement within the 0.02 mm systematic
  // bound plus 4 sigma of the fit (sigma from the fit's covariance, ~2-3 um).
  CHECK(m.at("sphere_size_max_abs_mm") < 0.02 + 4 * m.at("sphere_size_sigma_max_mm"));
  CHECK(m.at("spacing_max_abs_mm") < 0.02 + 4 * m.at("spacing_sigma_max_mm"));
  // Issue 3: systematic errors (mean deviations from the truth) < 0.02 mm.
  CHECK(m.at("systematic_max_abs_mm") < 0.02);
  REQUIRE(r.plots.size() == 3);
  for (const std::string& plot : r.plots) CHECK(std::filesystem::file_size(plot) > 1000);
}

TEST_CASE("gamma: an uncompensated projector gamma adds the error the model predicts", "[eval]") {
  sl::eval::EvalOptions o = options(2);
  o.out_dir.clear();
  SECTION("gamma 1.1: a ripple, no period errors") {
    // Peak phase error 0.030 rad: 0.21 projector px on the fine phase, i.e.
    // ~0.17 mm of depth at 0.83 mm/px (RMS ~0.12 mm), and 8.6 px on the
    // unit-frequency phase, inside the +-22.8 px the unwrapping tolerates.
    o.projector_gamma = 1.1;
    const sl::eval::EvalResult r = sl::eval::runPrecision(o);
    INFO(r.markdown);
    const auto& m = r.metrics;
    CHECK(m.at("period_error_fraction") == 0);
    CHECK(m.at("systematic_inlier_rms_mm") > 0.08);
    CHECK(m.at("systematic_inlier_rms_mm") < 0.2);
    // The ripple averages out of the mean over many fringes.
    CHECK(std::abs(m.at("systematic_mean_mm")) < 0.02);
  }
  SECTION("gamma 2.2: period errors over most of the image") {
    // The 3-step phase error of gamma 2.2 peaks at ~0.29 rad: ~84 projector px
    // on the unit-frequency phase, far beyond the +-22.8 px the 40-period
    // unwrapping tolerates, so most pixels get a wrong period; the rest carry
    // a ripple of up to ~2 px (~1.6 mm).
    o.projector_gamma = 2.2;
    const sl::eval::EvalResult r = sl::eval::runPrecision(o);
    INFO(r.markdown);
    const auto& m = r.metrics;
    CHECK(m.at("period_error_fraction") > 0.3);
    CHECK(m.at("systematic_inlier_rms_mm") > 0.5);
    CHECK(m.at("systematic_inlier_rms_mm") < 2.0);
  }
  SECTION("gamma 2.2 compensated in decoding: the linear projector's noise, no period errors") {
    // Issue 15: the gamma estimated from the first scan's own captures,
    // compensated in decoding: within 1.5x of the linear projector's noise
    // and no unwrapping failures.
    const sl::eval::EvalResult linear = sl::eval::runPrecision(o);
    o.projector_gamma = 2.2;
    o.compensate_gamma = true;
    const sl::eval::EvalResult r = sl::eval::runPrecision(o);
    INFO(r.markdown);
    const auto& m = r.metrics;
    CHECK(m.at("estimated_gamma") == Approx(2.2).margin(0.05));
    CHECK(m.at("period_error_fraction") == 0);
    CHECK(m.at("valid_fraction") >= 0.99 * linear.metrics.at("valid_fraction"));
    CHECK(m.at("std_mean_mm") <= 1.5 * linear.metrics.at("std_mean_mm"));
    CHECK(m.at("systematic_inlier_rms_mm") < 0.08);
  }
}

TEST_CASE("adaptive: the policy's pass beats every fixed choice over a stop and a go", "[eval][adaptive]") {
  // 6 scans: 4 stopped, then 2 moving at 60 mm/s.
  const sl::eval::EvalResult r = sl::eval::runAdaptive(options(6));
  const auto& m = r.metrics;
  CHECK(m.at("switches") == 1);
  CHECK(m.at("paused_scans") == 0);
  for (const char* fixed : {"fixed_accurate_", "fixed_accurate_compensated_", "fixed_fast_",
                            "fixed_fast_compensated_"}) {
    INFO(fixed);
    CHECK(m.at("adaptive_inlier_rms_mm") < m.at(std::string(fixed) + "inlier_rms_mm"));
    CHECK(m.at("adaptive_coverage") >= m.at(std::string(fixed) + "coverage"));
  }
  CHECK(m.at("adaptive_better_than_every_fixed") == 1);
}
