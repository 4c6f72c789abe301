// sl_eval: the paper's experiments (section 4) rerun on the simulated sensor
// with ground truth, through the daemon's pipeline (pipeline::Decoder,
// MotionCompensator, Triangulator; no DDS). Each experiment returns its
// numbers and a Markdown table, and writes PNG plots when given a folder.
// Synchronous, no threads; thread-compatible.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace sl::eval {

struct EvalOptions {
  int scans = 0;        // scans per condition; <= 0: the experiment's default
  std::string out_dir;  // PNG plots go here (created); empty: no plots
  // The simulated projector's intensity response (L / 255)^gamma; 1 = linear
  // (the LightCrafter 4500 in pattern mode). Not compensated by the pipeline.
  double projector_gamma = 1.0;
  // Compensate the projector's response in decoding: precision estimates the
  // gamma from its first scan's captures (pipeline::estimateProjectorGamma)
  // and decodes every scan with that response.
  bool compensate_gamma = false;
  // wall: write the scans (PLY), their true poses and the prior (TUM) to
  // this folder; or read them from one so written instead of scanning
  // (registration and evaluation only, e.g. to compare registration
  // settings). Empty: neither.
  std::string save_scans_dir;
  std::string load_scans_dir;
};

struct EvalResult {
  std::string markdown;                   // table(s) for a report
  std::map<std::string, double> metrics;  // named numbers (mm unless named otherwise)
  std::vector<std::string> plots;         // paths of the PNG files written
};

// 4.1 precision: consecutive scans of a flat matte wall at 500 mm; per-pixel
// depth standard deviation over the pixels valid in every scan (mean, max,
// RMS) next to the phase-noise floor sigma_phi = sqrt(2/N) sigma_I / B
// propagated per pixel through the triangulation (dz/du_p). Metrics:
// std_mean_mm, std_max_mm, std_rms_mm, theory_mean_mm, theory_max_mm,
// theory_rms_mm, ratio_rms (measured / theory), valid_pixels. Plot:
// precision_std.png (heat map).
EvalResult runPrecision(const EvalOptions& options);

// 4.3 motion: a relief (spheres and cones on a plate) at ~500 mm, the sensor
// moving 2 mm per image to the right, and accelerating (one pose per image,
// steps growing from 1 to 3 mm), vertical 3+3 pattern on a rig with a
// vertical camera-projector baseline ("top" camera). Depth against the ground
// truth at the compensation's reference image, without and with
// MotionCompensator (axis x). Metrics per condition (prefix "static_",
// "moving_", "compensated_", "compensated_no_window_", "accelerating_",
// "accelerating_compensated_"): rms_mm, relief_rms_mm, inlier_rms_mm,
// outlier_fraction, systematic_rms_mm, ripple_mm (half the 1..99 % spread of
// the scan-mean error along the cross-section), valid_fraction; and
// ripple_reduction, rms_reduction, accelerating_ripple_reduction,
// accelerating_rms_reduction. Plots: motion_cross_section.png,
// motion_accelerating_cross_section.png.
EvalResult runMotion(const EvalOptions& options);

// 4.1 accuracy: 6 cones on a plate at ~500 mm seen by the "top" camera
// (vertical baseline, vertical 3+3) and the "left" camera (horizontal
// baseline, horizontal 3+3) of one simulated sensor; each cone fitted per
// scan, apex distances 1 -> 2..6 against the truth (RMSE and std over scans,
// as the paper's Table 1). Metrics: <camera>_rmse_1_<k>_mm, worst_rmse_mm.
EvalResult runCones(const EvalOptions& options);

// 4.2 roughness: four rough height fields (seeded) at 500 mm, each scaled so
// that the ESD (std of the orthogonal distances to the best-fit plane) of
// its surface on a 30 cm^2 patch is the paper's reference ESD (0.008,
// 0.026, 0.053, 0.146 mm). The sensor's ESD on the patch per scan (averaged
// over the scans) and of the point-by-point mean of the scans. Metrics:
// S<i>_esd_truth_mm, S<i>_esd_truth_pixels_mm (truth at the camera's
// pixels), S<i>_esd_mm, S<i>_esd_error_mm, S<i>_esd_averaged_mm,
// S<i>_esd_averaged_error_mm, ranked_correctly, ranked_correctly_averaged
// (1 or 0), noise_esd_mm.
EvalResult runRoughness(const EvalOptions& options);

// vdi2634: an acceptance test in the spirit of VDI/VDE 2634 part 2 (optical
// 3D measuring systems, area scanning) on the "left" camera: probing error
// form P_F (range of the radial residuals of a least-squares sphere) and size
// P_S (fitted minus true diameter) of a 40 mm sphere at 7 positions in a
// 200 x 150 x 100 mm volume at 500 mm; sphere spacing error S_D of a ball bar
// (two 25 mm spheres 180 mm apart) at 7 poses; flatness error F (range of
// the residuals to the least-squares plane) of 200 x 150 mm of a plane at 7
// poses; `scans` measurements per pose. Each form statistic is also given
// for the points' noise alone, as the camera noise model predicts it.
// Metrics: sphere_form_max_mm, sphere_form997_max_mm (0.3 % discarded),
// sphere_form_ratio_max, sphere_form997_ratio_max (measured / expected),
// sphere_size_max_abs_mm, sphere_size_mean_mm, sphere_size_sigma_max_mm,
// sphere_deviation_mean_mm, sphere_gross_fraction (|residual| > 1 mm: period
// errors), spacing_max_abs_mm, spacing_mean_mm,
// spacing_sigma_max_mm, flatness_max_mm, flatness997_max_mm,
// flatness_ratio_max, flatness997_ratio_max, plane_deviation_mean_mm, plane_gross_points,
// plane_gross_fraction,
// systematic_max_abs_mm. Plots: vdi2634_{sphere,ball_bar,plane}_residuals.png.
EvalResult runVdi2634(const EvalOptions& options);

// Systematic errors (signed mean deviations from the truth) and the main
// accuracy figures of precision, cones and vdi2634 (their default scans, or
// `scans`), run with a linear projector, a mild gamma of 1.1 and gamma
// options.projector_gamma (2.2 when that is 1): how much error an
// uncompensated projector non-linearity adds, next to the model's phase
// error. Metrics: <experiment>.<metric>_<linear|gamma_1.1|gamma_G> for the
// rows of the table, systematic_max_abs_<...>_mm, phase_error_peak_rad_<...>,
// gamma; and the wall of precision at gamma G with the gamma estimated from
// the captures and compensated in decoding, next to the linear projector:
// compensated.<metric>, compensated_estimated_gamma,
// compensated_noise_ratio (std_mean against the linear projector's),
// compensated_target_met (1 when within 1.5x and without period errors).
EvalResult runGamma(const EvalOptions& options);

// 4.4 wall: a plaster-like wall larger than the field of view, a 50 cm
// horizontal and a 30 cm vertical pass at 12.5 mm/s scanned through the
// daemon's ScanEngine, registered by sl_register (pairwise and multi-way),
// compared with the true surface (tools/sl_eval/wall.cpp). `scans`: scans of
// the horizontal pass (default 21, 25 mm apart). Metrics:
// <pairwise|multiway>_<horizontal|vertical|merged>_{within_0.5mm_pct,
// p99_5_mm, mean_mm, std_mm, drift_mm, drift_deg}, refused_scans, scans,
// total_s. Plots: wall_<method>_distances.png (named in the markdown).
EvalResult runWall(const EvalOptions& options);

// adaptive (issue 33 item 4): motion's relief and rig, the sensor on a
// stop-go pass along x (1.6 s stopped, 2.4 s at 60 mm/s, repeated; a scan
// started every 0.4 s; `scans` scans, default 20). Each scan is taken with
// each fixed choice (6+6_vertical, the accurate 6-step pattern, and
// 3+3_vertical, each without and with MotionCompensator) and with the
// daemon's AdaptivePolicy choosing from the velocity (static -> 6+6, linear
// along x -> 3+3 compensated, its compensation seeded by the velocity
// through MotionPrior, and unseeded). Metrics per condition (prefix
// "fixed_accurate_", "fixed_accurate_compensated_", "fixed_fast_",
// "fixed_fast_compensated_", "adaptive_", "adaptive_unseeded_"): rms_mm,
// inlier_rms_mm, gross_fraction, coverage; and
// adaptive_better_than_every_fixed (1 when its inlier RMS is lower, its
// gross errors no more and its coverage at least those of each fixed
// choice, else 0), switches, paused_scans,
// prior_frames_at_expected.
EvalResult runAdaptive(const EvalOptions& options);

// Names accepted by runExperiment, in the order `all` runs them.
std::vector<std::string> experimentNames();
// The number of scans an experiment uses when EvalOptions::scans <= 0.
int defaultScans(const std::string& name);
// Throws std::invalid_argument on an unknown name.
EvalResult runExperiment(const std::string& name, const EvalOptions& options);

}  // namespace sl::eval
