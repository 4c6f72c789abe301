// Projector gamma (eval.h runGamma): precision, cones and vdi2634 with a
// linear, a mild and a strong uncompensated gamma, and precision's wall with
// the gamma estimated from its captures and compensated in decoding.
#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "common.h"
#include "eval.h"
#include "sl/pipeline/pattern_spec.h"

namespace sl::eval {

namespace {

// Peak phase error (rad) of an N-step phase shift when the projected
// sinusoid 0.5 + 0.5 cos passes through the response L^gamma (noise-free),
// over one period of the phase.
double gammaPhaseErrorPeak(double gamma, int steps) {
  double peak = 0;
  for (int i = 0; i < 3600; ++i) {
    const double phase = 2 * std::numbers::pi * i / 3600;
    double s = 0, c = 0;
    for (int k = 0; k < steps; ++k) {
      const double shift = 2 * std::numbers::pi * k / steps;
      const double intensity = std::pow(0.5 + 0.5 * std::cos(phase + shift), gamma);
      s -= intensity * std::sin(shift);
      c += intensity * std::cos(shift);
    }
    peak = std::max(peak, std::abs(std::remainder(std::atan2(s, c) - phase, 2 * std::numbers::pi)));
  }
  return peak;
}

}  // namespace

EvalResult runGamma(const EvalOptions& requested) {
  constexpr double kMildGamma = 1.1;
  const double gamma = requested.projector_gamma != 1.0 ? requested.projector_gamma : 2.2;
  struct Row {
    std::string experiment, key, label;
    int decimals;
  };
  const std::vector<Row> rows = {
      {"precision", "systematic_mean_mm", "precision: mean depth error (signed)", 4},
      {"precision", "systematic_rms_mm", "precision: RMS of the scan-mean depth error", 4},
      {"precision", "systematic_p99_mm", "precision: 99th percentile of that error, absolute", 4},
      {"precision", "std_mean_mm", "precision: mean per-pixel depth std (noise)", 4},
      {"precision", "period_error_fraction",
       "precision: fraction of pixels with a period error (> 5 mm)", 4},
      {"precision", "systematic_inlier_mean_mm",
       "precision: mean depth error without period errors", 4},
      {"precision", "systematic_inlier_rms_mm", "precision: RMS depth error without period errors",
       4},
      {"cones", "top_distance_mean_error_mm", "cones top: mean distance error (signed)", 4},
      {"cones", "top_worst_rmse_mm", "cones top: worst distance RMSE", 4},
      {"cones", "top_surface_mean_deviation_mm", "cones top: mean deviation from the true cones",
       4},
      {"cones", "left_distance_mean_error_mm", "cones left: mean distance error (signed)", 4},
      {"cones", "left_worst_rmse_mm", "cones left: worst distance RMSE", 4},
      {"cones", "left_surface_mean_deviation_mm", "cones left: mean deviation from the true cones",
       4},
      {"vdi2634", "sphere_gross_fraction", "vdi2634: fraction of sphere points off by > 1 mm", 4},
      {"vdi2634", "sphere_size_mean_mm", "vdi2634: P_S mean (signed)", 4},
      {"vdi2634", "sphere_size_max_abs_mm", "vdi2634: P_S, largest absolute", 4},
      {"vdi2634", "sphere_deviation_mean_mm",
       "vdi2634: mean radial deviation from the true spheres", 4},
      {"vdi2634", "sphere_form997_max_mm", "vdi2634: P_F (99.7 %) max", 3},
      {"vdi2634", "spacing_mean_mm", "vdi2634: S_D mean (signed)", 4},
      {"vdi2634", "spacing_max_abs_mm", "vdi2634: S_D, largest absolute", 4},
      {"vdi2634", "plane_deviation_mean_mm", "vdi2634: mean deviation from the true planes", 4},
      {"vdi2634", "flatness997_max_mm", "vdi2634: F (99.7 %) max", 3},
      {"vdi2634", "plane_gross_fraction", "vdi2634: fraction of plane points off by > 1 mm", 4}};
  // Signed mean deviations from the truth: the systematic errors.
  const std::vector<std::string> systematic = {"systematic_mean_mm",
                                               "top_distance_mean_error_mm",
                                               "left_distance_mean_error_mm",
                                               "top_surface_mean_deviation_mm",
                                               "left_surface_mean_deviation_mm",
                                               "sphere_size_mean_mm",
                                               "sphere_deviation_mean_mm",
                                               "spacing_mean_mm",
                                               "plane_deviation_mean_mm"};
  EvalResult result;
  auto& m = result.metrics;
  // Linear, a mild non-linearity the unwrapping survives, and the strong one.
  std::vector<double> gammas = {1.0, kMildGamma};
  if (gamma != kMildGamma) gammas.push_back(gamma);
  std::vector<std::map<std::string, EvalResult>> runs(gammas.size());
  for (std::size_t g = 0; g < gammas.size(); ++g)
    for (const char* experiment : {"precision", "cones", "vdi2634"}) {
      EvalOptions o = requested;
      o.out_dir.clear();  // the experiments' own runs write the plots
      o.projector_gamma = gammas[g];
      EvalResult& r = runs[g][experiment] = runExperiment(experiment, o);
      if (std::string(experiment) != "cones") continue;
      for (const std::string camera : {"top", "left"}) {
        double worst = 0;
        for (int k = 2; k <= 6; ++k)
          worst = std::max(worst, r.metrics.at(camera + "_rmse_1_" + std::to_string(k) + "_mm"));
        r.metrics[camera + "_worst_rmse_mm"] = worst;
      }
    }
  auto name = [](double g) { return g == 1.0 ? std::string("linear") : "gamma_" + fmt(g, 1); };
  std::ostringstream md;
  md << "### Projector gamma: systematic errors with a linear projector (gamma 1, the "
        "LightCrafter in pattern mode) and with an uncompensated gamma\n\n"
     << "| quantity (mm unless a fraction) |";
  for (double g : gammas) md << " gamma " << fmt(g, 1) << " |";
  for (std::size_t g = 1; g < gammas.size(); ++g)
    md << " added by gamma " << fmt(gammas[g], 1) << " |";
  md << "\n|---|";
  for (std::size_t g = 1; g < 2 * gammas.size(); ++g) md << "---|";
  md << "\n";
  for (const Row& row : rows) {
    md << "| " << row.label << " |";
    for (std::size_t g = 0; g < gammas.size(); ++g) {
      const double v = runs[g][row.experiment].metrics.at(row.key);
      m[row.experiment + "." + row.key + "_" + name(gammas[g])] = v;
      md << " " << fmt(v, row.decimals) << " |";
    }
    const double base = runs[0][row.experiment].metrics.at(row.key);
    for (std::size_t g = 1; g < gammas.size(); ++g) {
      const double added = runs[g][row.experiment].metrics.at(row.key) - base;
      md << " " << (added >= 0 ? "+" : "") << fmt(added, row.decimals) << " |";
    }
    md << "\n";
  }
  std::vector<double> worst(gammas.size(), 0.0);
  for (const Row& row : rows)
    if (std::find(systematic.begin(), systematic.end(), row.key) != systematic.end())
      for (std::size_t g = 0; g < gammas.size(); ++g)
        worst[g] = std::max(worst[g], std::abs(runs[g][row.experiment].metrics.at(row.key)));
  for (std::size_t g = 0; g < gammas.size(); ++g)
    m["systematic_max_abs_" + name(gammas[g]) + "_mm"] = worst[g];
  m["gamma"] = gamma;
  // The model behind the table: the gamma's phase error on the fine phase and
  // on the unit-frequency phase, against the half fine period the latter must
  // stay within for the unwrapping to pick the right period.
  const pipeline::PatternSpec spec = pattern33("3+3_horizontal", pipeline::Direction::kHorizontal);
  const double width = spec.axisLength(true), period = spec.finestPeriod(width);
  md << "\nThe " << spec.steps << "-step phase of a sinusoid seen through the response L^gamma "
     << "has a periodic error (noise-free peak below). On the fine phase it is a depth ripple "
        "with a third of the fringe period; the unit-frequency phase that picks the period must "
        "stay within +-"
     << fmt(period / 2, 1) << " projector px (" << kFringes << " periods of " << fmt(period, 1)
     << " px) or the point jumps by a whole period (~35 mm here):\n\n"
     << "| gamma | peak phase error / rad | on the fine phase / projector px | on the "
        "unit-frequency phase / projector px | largest abs systematic error (signed means) / mm "
        "|\n|---|---|---|---|---|\n";
  for (std::size_t g = 0; g < gammas.size(); ++g) {
    const double peak = gammaPhaseErrorPeak(gammas[g], spec.steps);
    m["phase_error_peak_rad_" + name(gammas[g])] = peak;
    md << "| " << fmt(gammas[g], 1) << " | " << fmt(peak, 3) << " | "
       << fmt(peak * period / (2 * std::numbers::pi), 2) << " | "
       << fmt(peak * width / (2 * std::numbers::pi), 1) << " | " << fmt(worst[g], 4) << " |\n";
  }
  // The same wall at gamma G compensated in decoding (gamma estimated from
  // the first scan's own captures), against the linear projector.
  {
    EvalOptions o = requested;
    o.out_dir.clear();
    o.projector_gamma = gamma;
    o.compensate_gamma = true;
    const EvalResult compensated = runPrecision(o);
    const auto& linear = runs[0]["precision"].metrics;
    const auto& uncompensated = runs.back()["precision"].metrics;
    for (const char* key : {"std_mean_mm", "std_rms_mm", "period_error_fraction",
                            "valid_fraction", "systematic_inlier_rms_mm", "systematic_mean_mm"})
      m[std::string("compensated.") + key] = compensated.metrics.at(key);
    m["compensated_estimated_gamma"] = compensated.metrics.at("estimated_gamma");
    const double ratio = compensated.metrics.at("std_mean_mm") / linear.at("std_mean_mm");
    m["compensated_noise_ratio"] = ratio;
    const bool met = ratio <= 1.5 && compensated.metrics.at("period_error_fraction") == 0 &&
                     compensated.metrics.at("valid_fraction") >= 0.99 * linear.at("valid_fraction");
    m["compensated_target_met"] = met ? 1.0 : 0.0;
    md << "\n### The wall at gamma " << fmt(gamma, 1)
       << " compensated in decoding\n\nThe gamma estimated from the first scan's own captures "
          "(the one that makes the unit-frequency and the fine phase agree best): "
       << fmt(m["compensated_estimated_gamma"], 3)
       << "; every scan decoded with the phase of each set corrected for L^gamma.\n\n"
       << "| precision, wall at 500 mm | linear | gamma " << fmt(gamma, 1) << " | gamma "
       << fmt(gamma, 1) << " compensated |\n|---|---|---|---|\n";
    struct Line {
      const char* key;
      const char* label;
      int decimals;
    };
    for (const Line& l : {Line{"std_mean_mm", "mean per-pixel depth std / mm", 4},
                          Line{"period_error_fraction", "fraction of pixels with a period error", 4},
                          Line{"valid_fraction", "fraction of the image valid in every scan", 4},
                          Line{"systematic_inlier_rms_mm", "RMS depth error without period errors / mm", 4}})
      md << "| " << l.label << " | " << fmt(linear.at(l.key), l.decimals) << " | "
         << fmt(uncompensated.at(l.key), l.decimals) << " | "
         << fmt(compensated.metrics.at(l.key), l.decimals) << " |\n";
    md << "\nIssue 15's target, compensated noise within 1.5x of the linear projector's and no "
          "unwrapping failures: "
       << (met ? "met" : "NOT met") << " (noise ratio " << fmt(ratio, 3) << ", period errors on "
       << fmt(100 * compensated.metrics.at("period_error_fraction"), 2) << " %, valid "
       << fmt(100 * compensated.metrics.at("valid_fraction"), 2) << " % against "
       << fmt(100 * linear.at("valid_fraction"), 2) << " %).\n";
  }
  md << "\nIssue 3's target, systematic errors < 0.02 mm with gamma off: "
     << (worst[0] < 0.02 ? "met" : "NOT met") << " (" << fmt(worst[0], 4)
     << " mm). A mild gamma leaves the signed means small (the ripple averages out over the "
        "fringes) but adds its ripple to the RMS, form and flatness errors; gamma "
     << fmt(gammas.back(), 1)
     << " breaks the unwrapping wherever its unit-frequency error passes the half period, and "
        "the period errors dominate every figure that keeps those points.\n";
  result.markdown = md.str();
  return result;
}

}  // namespace sl::eval
