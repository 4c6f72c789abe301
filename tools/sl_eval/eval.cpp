#include "eval.h"
#include "sl/pipeline/projector_response.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "common.h"
#include "plots.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/motion_compensation.h"
#include "sl/pipeline/triangulator.h"

namespace sl::eval {

EvalResult runPrecision(const EvalOptions& requested) {
  const EvalOptions options = withDefaultScans(requested, "precision");
  if (options.scans < 2) throw std::invalid_argument("precision: needs at least 2 scans");
  // Projector 150 mm to the right, axes crossing at 550 mm (config/sim.yaml).
  const pipeline::CameraProjectorCalibration calibration = rig({150, 0, 0}, 550);
  const pipeline::PatternSpec spec = pattern33("3+3_horizontal", pipeline::Direction::kHorizontal);
  drivers::SimConfig config = baseConfig(calibration, spec, options);
  config.scene.planes = {drivers::SimPlane{{0, 0, 500}, {0, 0, -1}, 0.8}};  // matte wall, 50 cm
  const auto sensor = drivers::SimulatedSensor::create(config);
  pipeline::DecoderOptions decoder_options;
  double estimated_gamma = 1.0;
  if (options.compensate_gamma) {
    // From the captures themselves: the first scan's frames.
    estimated_gamma = pipeline::estimateProjectorGamma(
                          spec, renderScan(*sensor, spec.name, spec.frameCount(), 100), 8)
                          .gamma;
    decoder_options.projector_response = pipeline::gammaResponse(estimated_gamma);
  }
  const pipeline::Decoder decoder(spec, decoder_options);
  pipeline::TriangulatorOptions triangulation;
  triangulation.use = pipeline::TriangulatorOptions::Use::kColumns;
  triangulation.min_depth_mm = 200;
  triangulation.max_depth_mm = 1500;
  const pipeline::Triangulator triangulator(calibration, triangulation);

  const cv::Size size(calibration.camera.width, calibration.camera.height);
  cv::Mat sum(size, CV_64FC1, cv::Scalar(0)), sum_sq(size, CV_64FC1, cv::Scalar(0));
  cv::Mat sum_a(size, CV_64FC1, cv::Scalar(0)), sum_b(size, CV_64FC1, cv::Scalar(0));
  cv::Mat count(size, CV_32SC1, cv::Scalar(0));
  pipeline::ProjectorMaps last;
  for (int k = 0; k < options.scans; ++k) {
    last = decoder.decode(renderScan(*sensor, spec.name, spec.frameCount(), 100 + k), 8);
    const cv::Mat z = depthOf(triangulator.triangulate(last));
    for (int r = 0; r < size.height; ++r)
      for (int c = 0; c < size.width; ++c) {
        const double v = z.at<float>(r, c);
        if (std::isnan(v)) continue;
        sum.at<double>(r, c) += v;
        sum_sq.at<double>(r, c) += v * v;
        sum_a.at<double>(r, c) += last.offset.at<float>(r, c);
        sum_b.at<double>(r, c) += last.modulation.at<float>(r, c);
        ++count.at<int>(r, c);
      }
  }
  // dz/du_p per pixel: triangulate the last scan's columns shifted by +-0.5 px.
  pipeline::ProjectorMaps plus = last, minus = last;  // the maps share buffers: new ones for up
  plus.up = cv::Mat(last.up + 0.5);
  minus.up = cv::Mat(last.up - 0.5);
  const cv::Mat z_plus = depthOf(triangulator.triangulate(plus));
  const cv::Mat z_minus = depthOf(triangulator.triangulate(minus));

  // Phase-noise floor: N = 3 steps, sigma_I^2 = gain * A + read^2 + 1/12 (8-bit
  // quantisation), sigma_phi = sqrt(2/N) sigma_I / B, sigma_up = sigma_phi *
  // period / (2 pi), sigma_z = |dz/du_p| sigma_up.
  const double steps = spec.steps;
  const double period = spec.finestPeriod(spec.axisLength(true));  // projector px
  cv::Mat std_map(size, CV_32FC1, cv::Scalar(kNaN));
  double std_sum = 0, std_max = 0, var_sum = 0, theory_sum = 0, theory_max = 0, theory_var = 0;
  long long valid = 0;
  const int n = options.scans;
  // Systematic error: the per-pixel mean depth over the scans minus the truth.
  const cv::Mat& gt_depth = sensor->groundTruth().depth_mm;
  // Errors beyond kPeriodErrorMm are period (unwrapping) errors: one fine
  // period is ~35 mm of depth here.
  constexpr double kPeriodErrorMm = 5.0;
  double error_sum = 0, error_sq = 0, inlier_sum = 0, inlier_sq = 0;
  double a_sum = 0, b_sum = 0, sigma_i_sum = 0, dz_sum = 0;  // for the worked example
  long long gross = 0;
  std::vector<double> abs_errors;
  for (int r = 0; r < size.height; ++r)
    for (int c = 0; c < size.width; ++c) {
      if (count.at<int>(r, c) != n) continue;
      const double mean = sum.at<double>(r, c) / n;
      const double variance = std::max(0.0, (sum_sq.at<double>(r, c) - n * mean * mean) / (n - 1));
      const double dz_dup = double(z_plus.at<float>(r, c)) - double(z_minus.at<float>(r, c));
      if (std::isnan(dz_dup)) continue;
      const double a = sum_a.at<double>(r, c) / n, b = sum_b.at<double>(r, c) / n;
      const double sigma_i = std::sqrt(config.gain_dn_per_electron * a +
                                       config.read_noise_dn * config.read_noise_dn + 1.0 / 12.0);
      const double sigma_phi = std::sqrt(2.0 / steps) * sigma_i / b;
      a_sum += a;
      b_sum += b;
      sigma_i_sum += sigma_i;
      dz_sum += std::abs(dz_dup);
      const double theory = std::abs(dz_dup) * sigma_phi * period / (2 * std::numbers::pi);
      const double s = std::sqrt(variance);
      std_map.at<float>(r, c) = static_cast<float>(s);
      std_sum += s;
      std_max = std::max(std_max, s);
      var_sum += variance;
      theory_sum += theory;
      theory_max = std::max(theory_max, theory);
      theory_var += theory * theory;
      const double error = mean - double(gt_depth.at<float>(r, c));
      error_sum += error;
      error_sq += error * error;
      abs_errors.push_back(std::abs(error));
      if (std::abs(error) > kPeriodErrorMm) {
        ++gross;
      } else {
        inlier_sum += error;
        inlier_sq += error * error;
      }
      ++valid;
    }
  if (valid == 0) throw std::runtime_error("precision: no pixel valid in every scan");
  EvalResult result;
  auto& m = result.metrics;
  m["valid_pixels"] = double(valid);
  m["valid_fraction"] = double(valid) / double(size.area());
  m["std_mean_mm"] = std_sum / valid;
  m["std_max_mm"] = std_max;
  m["std_rms_mm"] = std::sqrt(var_sum / valid);
  m["theory_mean_mm"] = theory_sum / valid;
  m["theory_max_mm"] = theory_max;
  m["theory_rms_mm"] = std::sqrt(theory_var / valid);
  m["ratio_rms"] = m["std_rms_mm"] / m["theory_rms_mm"];
  m["systematic_mean_mm"] = error_sum / valid;
  m["systematic_rms_mm"] = std::sqrt(error_sq / valid);
  m["systematic_p99_mm"] = percentile(abs_errors, 0.99);
  m["period_error_fraction"] = double(gross) / double(valid);
  if (options.compensate_gamma) m["estimated_gamma"] = estimated_gamma;
  m["offset_mean_dn"] = a_sum / valid;
  m["modulation_mean_dn"] = b_sum / valid;
  m["sigma_i_mean_dn"] = sigma_i_sum / valid;
  m["dz_dup_mean_mm_per_px"] = dz_sum / valid;
  m["systematic_inlier_mean_mm"] = inlier_sum / double(std::max<long long>(valid - gross, 1));
  m["systematic_inlier_rms_mm"] =
      std::sqrt(inlier_sq / double(std::max<long long>(valid - gross, 1)));

  std::ostringstream md;
  md << "### Precision: " << n << " scans of a flat matte wall at 500 mm (3+3 horizontal, "
     << kFringes << " fringes, 150 mm baseline)\n\n"
     << "| | mean / mm | max / mm | RMS / mm |\n|---|---|---|---|\n"
     << "| depth std, simulated sensor | " << fmt(m["std_mean_mm"], 4) << " | "
     << fmt(m["std_max_mm"], 4) << " | " << fmt(m["std_rms_mm"], 4) << " |\n"
     << "| phase-noise floor sqrt(2/N) sigma_I / B -> z | " << fmt(m["theory_mean_mm"], 4) << " | "
     << fmt(m["theory_max_mm"], 4) << " | " << fmt(m["theory_rms_mm"], 4) << " |\n"
     << "| paper, SL Sensor (real) | 0.070 | 0.251 | |\n\n"
     << "Measured / floor (RMS over " << valid << " pixels valid in every scan, "
     << fmt(100 * m["valid_fraction"], 1) << " % of the image): " << fmt(m["ratio_rms"], 3)
     << ". Mean over the pixels: offset A " << fmt(m["offset_mean_dn"], 1) << " DN, modulation B "
     << fmt(m["modulation_mean_dn"], 1) << " DN, sigma_I " << fmt(m["sigma_i_mean_dn"], 3)
     << " DN, |dz/du_p| " << fmt(m["dz_dup_mean_mm_per_px"], 3) << " mm per projector px, period "
     << fmt(period, 1) << " projector px. (Max of a per-pixel std over " << n
     << " scans is a sampling extreme; the floor's "
     << "max is not.)\n\n"
     << "Systematic error (per-pixel mean of the " << n << " scans minus the true depth): mean "
     << fmt(m["systematic_mean_mm"], 4) << " mm, RMS " << fmt(m["systematic_rms_mm"], 4)
     << " mm, 99th percentile of |error| " << fmt(m["systematic_p99_mm"], 4)
     << " mm (the RMS and percentile include the noise left in the mean, std / sqrt(" << n
     << ")); period errors (|error| > 5 mm) on " << fmt(100 * m["period_error_fraction"], 2)
     << " % of the pixels, without them mean " << fmt(m["systematic_inlier_mean_mm"], 4)
     << " mm, RMS " << fmt(m["systematic_inlier_rms_mm"], 4) << " mm"
     << (options.projector_gamma != 1.0
             ? "; projector gamma " + fmt(options.projector_gamma, 2) +
                   (options.compensate_gamma
                        ? ", compensated in decoding with the gamma estimated from the first "
                          "scan, " + fmt(estimated_gamma, 3)
                        : "") +
                   "."
             : ".")
     << "\n";
  result.markdown = md.str();
  if (!options.out_dir.empty()) {
    const std::string path = plotPath(options, "precision_std.png");
    writeHeatMap(path, std_map, std::max(0.05, 2.0 * m["std_rms_mm"]),
                 "Depth std per pixel over " + std::to_string(n) + " scans (wall at 500 mm)", "mm");
    result.plots.push_back(path);
  }
  return result;
}

EvalResult runMotion(const EvalOptions& requested) {
  const EvalOptions options = withDefaultScans(requested, "motion");
  if (options.scans < 1) throw std::invalid_argument("motion: needs at least 1 scan");
  // "Top" camera 150 mm above the projector: vertical baseline, axes crossing
  // at 520 mm; the vertical 3+3 pattern encodes projector rows.
  const pipeline::CameraProjectorCalibration calibration = rig({0, 150, 0}, 520);
  const pipeline::PatternSpec spec = pattern33("3+3_vertical", pipeline::Direction::kVertical);
  drivers::SimConfig config = baseConfig(calibration, spec, options);
  // A relief on a plate at 520 mm: two spherical caps and two cones.
  config.scene.planes = {drivers::SimPlane{{0, 0, 520}, {0, 0, -1}, 0.8}};
  config.scene.spheres = {drivers::SimSphere{{-70, 0, 550}, 45, 0.8},
                          drivers::SimSphere{{20, -60, 560}, 50, 0.75}};
  config.scene.cones = {drivers::SimCone{{40, 0, 520}, {0, 0, -1}, 30, 15, 0.8},
                        drivers::SimCone{{-10, 60, 520}, {0, 0, -1}, 25, 12, 0.7}};
  drivers::SimConfig moving_config = config;
  moving_config.motion.velocity_mm_s = {2.0 * kFps, 0, 0};  // 2 mm per image to the right
  // Accelerating: one pose per image, the steps between consecutive images
  // growing linearly from 1 to 3 mm (1, 1.5, 2, 2.5, 3 mm for 6 images).
  drivers::SimConfig accelerating_config = config;
  std::vector<double> accelerating_x;  // sensor position per image (mm)
  {
    const int n = spec.frameCount();
    double x = 0;
    for (int i = 0; i < n; ++i) {
      accelerating_x.push_back(x);
      Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
      pose.translation() = Eigen::Vector3d(x, 0, 0);
      accelerating_config.motion.poses.push_back(pose);
      x += 1.0 + 2.0 * i / std::max(n - 2, 1);
    }
  }
  const auto still = drivers::SimulatedSensor::create(config);
  const auto moving = drivers::SimulatedSensor::create(moving_config);
  const auto accelerating = drivers::SimulatedSensor::create(accelerating_config);

  const pipeline::Decoder decoder(spec, pipeline::DecoderOptions{});
  pipeline::TriangulatorOptions triangulation;
  triangulation.use = pipeline::TriangulatorOptions::Use::kRows;
  triangulation.min_depth_mm = 200;
  triangulation.max_depth_mm = 1500;
  const pipeline::Triangulator triangulator(calibration, triangulation);
  pipeline::MotionCompensationOptions mc;
  mc.axis = pipeline::MotionCompensationOptions::Axis::kX;
  const int frames = spec.frameCount();
  const int reference = frames / 2;  // the compensator's default (middle) frame
  mc.reference_frame = reference;
  const pipeline::MotionCompensator compensator(mc);
  pipeline::MotionCompensationOptions mc_no_window = mc;
  mc_no_window.window = false;
  const pipeline::MotionCompensator compensator_no_window(mc_no_window);

  // Ground truth at the reference image; the static sensor's is image 0's.
  const cv::Mat gt_moving = moving->groundTruthAt(0, reference).depth_mm;
  const cv::Mat gt_still = still->groundTruth().depth_mm;
  const cv::Mat gt_accelerating = accelerating->groundTruthAt(0, reference).depth_mm;
  // Evaluated pixels: away from depth steps (by the largest image motion of
  // a sequence, 3 images x ~10 px) and from the image border.
  auto evaluationMask = [&](const cv::Mat& gt) {
    cv::Mat steps(gt.size(), CV_8UC1, cv::Scalar(0));
    for (int r = 1; r < gt.rows - 1; ++r)
      for (int c = 1; c < gt.cols - 1; ++c) {
        const float z = gt.at<float>(r, c);
        const float dx = std::abs(gt.at<float>(r, c + 1) - z),
                    dy = std::abs(gt.at<float>(r + 1, c) - z);
        if (std::isnan(z) || !(dx < 1.0f) || !(dy < 1.0f)) steps.at<std::uint8_t>(r, c) = 255;
      }
    cv::dilate(steps, steps, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(61, 61)));
    cv::Mat mask = 255 - steps;
    const int border = 40;
    mask.colRange(0, border).setTo(0);
    mask.colRange(gt.cols - border, gt.cols).setTo(0);
    mask.rowRange(0, border).setTo(0);
    mask.rowRange(gt.rows - border, gt.rows).setTo(0);
    return mask;
  };
  const cv::Mat mask_moving = evaluationMask(gt_moving), mask_still = evaluationMask(gt_still);
  const cv::Mat mask_accelerating = evaluationMask(gt_accelerating);
  // Relief: pixels standing > 0.5 mm off the plate.
  auto reliefMask = [](const cv::Mat& gt, const cv::Mat& mask) {
    cv::Mat relief = mask.clone();
    for (int r = 0; r < gt.rows; ++r)
      for (int c = 0; c < gt.cols; ++c)
        if (!(gt.at<float>(r, c) < 519.5f)) relief.at<std::uint8_t>(r, c) = 0;
    return relief;
  };
  const cv::Mat relief_moving = reliefMask(gt_moving, mask_moving);
  const cv::Mat relief_still = reliefMask(gt_still, mask_still);
  const cv::Mat relief_accelerating = reliefMask(gt_accelerating, mask_accelerating);
  const int section_row = 540;        // through the first sphere and cone (y = 0)
  constexpr double kOutlierMm = 2.0;  // |error| above: a gross (unwrapping) error

  struct Condition {
    std::string key, label;
    const cv::Mat* gt;
    const cv::Mat* mask;
    const cv::Mat* relief;
    double sq_sum = 0, relief_sq_sum = 0, inlier_sq_sum = 0;
    long long count = 0, relief_count = 0, evaluated = 0, outliers = 0;
    cv::Mat error_sum{}, error_count{};  // per pixel over scans (mask pixels, no gross errors)
    cv::Mat first_depth{};
  };
  std::vector<Condition> conditions = {
      {"static_", "static sensor", &gt_still, &mask_still, &relief_still},
      {"moving_", "moving 2 mm/image, no compensation", &gt_moving, &mask_moving, &relief_moving},
      {"compensated_", "moving 2 mm/image, motion compensation (x, daemon defaults)", &gt_moving,
       &mask_moving, &relief_moving},
      {"compensated_no_window_", "moving 2 mm/image, motion compensation (x, window: false)",
       &gt_moving, &mask_moving, &relief_moving},
      {"accelerating_", "accelerating 1 -> 3 mm/image, no compensation", &gt_accelerating,
       &mask_accelerating, &relief_accelerating},
      {"accelerating_compensated_",
       "accelerating 1 -> 3 mm/image, motion compensation (x, daemon defaults)", &gt_accelerating,
       &mask_accelerating, &relief_accelerating}};
  double shift_sum = 0, shift_no_window_sum = 0;
  int shift_count = 0, shift_no_window_count = 0, rejected_estimates = 0;
  std::vector<std::vector<double>> first_shifts;
  std::vector<double> first_accelerating_shifts;
  auto imageSet = [&](const std::vector<cv::Mat>& images) {
    pipeline::ImageSet set;
    set.pattern_name = spec.name;
    pipeline::CameraImages camera_images;
    camera_images.camera_id = "sim_top";
    camera_images.frames = images;
    for (int i = 0; i < frames; ++i)
      camera_images.stamps_ns.push_back(static_cast<std::int64_t>(i * 1e9 / kFps));
    set.cameras.push_back(camera_images);
    return set;
  };
  for (int k = 0; k < options.scans; ++k) {
    std::vector<cv::Mat> depths(conditions.size());
    depths[0] = depthOf(triangulator.triangulate(
        decoder.decode(renderScan(*still, spec.name, frames, 200 + k), 8)));
    const std::vector<cv::Mat> images = renderScan(*moving, spec.name, frames, 200 + k);
    depths[1] = depthOf(triangulator.triangulate(decoder.decode(images, 8)));
    const pipeline::ImageSet set = imageSet(images);
    pipeline::MotionEstimate estimate;
    const auto aligned = compensator.compensate(set, &estimate);
    for (int i = 0; i < frames; ++i)
      if (i != reference) {
        shift_sum += std::abs(estimate.shifts_px[0][i]) / std::abs(i - reference);
        ++shift_count;
      }
    depths[2] = depthOf(triangulator.triangulate(decoder.decode(aligned->cameras[0].frames, 8)));
    if (!estimate.all_within_limit) ++rejected_estimates;
    pipeline::MotionEstimate estimate_no_window;
    const auto aligned_no_window = compensator_no_window.compensate(set, &estimate_no_window);
    for (int i = 0; i < frames; ++i)
      if (i != reference) {
        shift_no_window_sum +=
            std::abs(estimate_no_window.shifts_px[0][i]) / std::abs(i - reference);
        ++shift_no_window_count;
      }
    depths[3] =
        depthOf(triangulator.triangulate(decoder.decode(aligned_no_window->cameras[0].frames, 8)));
    if (k == 0) first_shifts = {estimate.shifts_px[0], estimate_no_window.shifts_px[0]};
    const std::vector<cv::Mat> accelerating_images =
        renderScan(*accelerating, spec.name, frames, 200 + k);
    depths[4] = depthOf(triangulator.triangulate(decoder.decode(accelerating_images, 8)));
    pipeline::MotionEstimate accelerating_estimate;
    const auto accelerating_aligned =
        compensator.compensate(imageSet(accelerating_images), &accelerating_estimate);
    depths[5] = depthOf(
        triangulator.triangulate(decoder.decode(accelerating_aligned->cameras[0].frames, 8)));
    if (!accelerating_estimate.all_within_limit) ++rejected_estimates;
    if (k == 0) first_accelerating_shifts = accelerating_estimate.shifts_px[0];
    for (std::size_t j = 0; j < conditions.size(); ++j) {
      Condition& cond = conditions[j];
      const cv::Mat& z = depths[j];
      if (k == 0) {
        cond.first_depth = z;
        cond.error_sum = cv::Mat(z.size(), CV_64FC1, cv::Scalar(0));
        cond.error_count = cv::Mat(z.size(), CV_32SC1, cv::Scalar(0));
      }
      for (int r = 0; r < z.rows; ++r)
        for (int c = 0; c < z.cols; ++c) {
          if (!cond.mask->at<std::uint8_t>(r, c)) continue;
          ++cond.evaluated;
          const double e = double(z.at<float>(r, c)) - double(cond.gt->at<float>(r, c));
          if (std::isnan(e)) continue;
          cond.sq_sum += e * e;
          ++cond.count;
          if (std::abs(e) > kOutlierMm) {
            ++cond.outliers;
          } else {
            cond.inlier_sq_sum += e * e;
            cond.error_sum.at<double>(r, c) += e;
            ++cond.error_count.at<int>(r, c);
          }
          if (cond.relief->at<std::uint8_t>(r, c)) {
            cond.relief_sq_sum += e * e;
            ++cond.relief_count;
          }
        }
    }
  }

  EvalResult result;
  auto& m = result.metrics;
  for (const Condition& cond : conditions) {
    m[cond.key + "rms_mm"] = std::sqrt(cond.sq_sum / std::max<long long>(cond.count, 1));
    m[cond.key + "relief_rms_mm"] =
        std::sqrt(cond.relief_sq_sum / std::max<long long>(cond.relief_count, 1));
    m[cond.key + "valid_fraction"] = double(cond.count) / std::max<long long>(cond.evaluated, 1);
    m[cond.key + "outlier_fraction"] = double(cond.outliers) / std::max<long long>(cond.count, 1);
    m[cond.key + "inlier_rms_mm"] =
        std::sqrt(cond.inlier_sq_sum / std::max<long long>(cond.count - cond.outliers, 1));
    // Systematic part: the per-pixel error averaged over the scans (noise / sqrt(scans)).
    double mean_sq = 0;
    long long mean_count = 0;
    std::vector<double> section;
    for (int r = 0; r < cond.error_sum.rows; ++r)
      for (int c = 0; c < cond.error_sum.cols; ++c) {
        if (cond.error_count.at<int>(r, c) != options.scans) continue;
        const double e = cond.error_sum.at<double>(r, c) / options.scans;
        mean_sq += e * e;
        ++mean_count;
        if (r == section_row && cond.relief->at<std::uint8_t>(r, c)) section.push_back(e);
      }
    m[cond.key + "systematic_rms_mm"] = std::sqrt(mean_sq / std::max<long long>(mean_count, 1));
    m[cond.key + "ripple_mm"] = 0.5 * (percentile(section, 0.99) - percentile(section, 0.01));
  }
  m["ripple_reduction"] = m["moving_ripple_mm"] / m["compensated_ripple_mm"];
  m["rms_reduction"] = m["moving_relief_rms_mm"] / m["compensated_relief_rms_mm"];
  m["ripple_reduction_no_window"] = m["moving_ripple_mm"] / m["compensated_no_window_ripple_mm"];
  m["rms_reduction_no_window"] =
      m["moving_relief_rms_mm"] / m["compensated_no_window_relief_rms_mm"];
  m["estimated_shift_px_per_image"] = shift_sum / std::max(shift_count, 1);
  m["estimated_shift_no_window_px_per_image"] =
      shift_no_window_sum / std::max(shift_no_window_count, 1);
  m["accelerating_ripple_reduction"] =
      m["accelerating_ripple_mm"] / m["accelerating_compensated_ripple_mm"];
  m["accelerating_rms_reduction"] =
      m["accelerating_relief_rms_mm"] / m["accelerating_compensated_relief_rms_mm"];
  m["scans_with_rejected_estimate"] = rejected_estimates;
  m["true_shift_px_per_image_at_520mm"] = calibration.camera.fx * 2.0 / 520.0;

  std::ostringstream md;
  md << "### Motion: relief at 500-520 mm, sensor moving 2 mm per image to the right (and "
        "accelerating from 1 to 3 mm per image), "
     << "vertical 3+3, vertical baseline, " << options.scans << " scan(s)\n\n"
     << "| condition | RMS error, relief / mm | RMS error, all / mm | RMS without gross errors "
        "/ mm | gross errors (> 2 mm) | systematic RMS (error of the scan mean) / mm | ripple on "
        "the relief's cross-section (half 1-99 % spread of the scan-mean error) / mm | "
        "valid |\n|---|---|---|---|---|---|---|---|\n";
  for (const Condition& cond : conditions)
    md << "| " << cond.label << " | " << fmt(m[cond.key + "relief_rms_mm"], 4) << " | "
       << fmt(m[cond.key + "rms_mm"], 4) << " | " << fmt(m[cond.key + "inlier_rms_mm"], 4) << " | "
       << fmt(100 * m[cond.key + "outlier_fraction"], 2) << " % | "
       << fmt(m[cond.key + "systematic_rms_mm"], 4) << " | " << fmt(m[cond.key + "ripple_mm"], 4)
       << " | " << fmt(100 * m[cond.key + "valid_fraction"], 1) << " % |\n";
  std::vector<double> true_accelerating;  // image shift of the plate (px)
  for (double x : accelerating_x)
    true_accelerating.push_back(-(x - accelerating_x[reference]) * calibration.camera.fx / 520.0);
  auto list = [](const std::vector<double>& v) {
    std::string s;
    for (double x : v) s += (s.empty() ? "" : ", ") + fmt(x, 2);
    return s;
  };
  md << "\nCompensation (daemon defaults): ripple reduced " << fmt(m["ripple_reduction"], 2)
     << "x, relief RMS " << fmt(m["rms_reduction"], 2) << "x; with window: false "
     << fmt(m["ripple_reduction_no_window"], 2) << "x and " << fmt(m["rms_reduction_no_window"], 2)
     << "x. Estimated shifts of scan 1 (px, per image): "
     << "[" << list(first_shifts[0]) << "] with the Hann window (" << rejected_estimates << " of "
     << options.scans << " scans had an estimate beyond max_shift_px, replaced by 0), ["
     << list(first_shifts[1]) << "] without. Mean |shift| per image "
     << fmt(m["estimated_shift_px_per_image"], 2) << " / "
     << fmt(m["estimated_shift_no_window_px_per_image"], 2)
     << " px (plate at 520 mm: " << fmt(m["true_shift_px_per_image_at_520mm"], 2)
     << " px; nearer relief moves up to 5 % more).\n\nAccelerating sensor (steps of 1, 1.5, 2, "
        "2.5, 3 mm between images): ripple reduced "
     << fmt(m["accelerating_ripple_reduction"], 2) << "x, relief RMS "
     << fmt(m["accelerating_rms_reduction"], 2) << "x; estimated shifts of scan 1 ["
     << list(first_accelerating_shifts) << "] px, true on the plate [" << list(true_accelerating)
     << "] px.\n\nIssue 7's targets: ripple reduced >= 5x ("
     << (m["ripple_reduction"] >= 5 ? "met" : "NOT met") << " at 2 mm/image, "
     << (m["accelerating_ripple_reduction"] >= 5 ? "met" : "NOT met")
     << " accelerating); compensated RMS depth error on the relief < 0.1 mm ("
     << fmt(m["compensated_relief_rms_mm"], 4) << " mm, "
     << (m["compensated_relief_rms_mm"] < 0.1 ? "met" : "NOT met") << "; accelerating "
     << fmt(m["accelerating_compensated_relief_rms_mm"], 4) << " mm, "
     << (m["accelerating_compensated_relief_rms_mm"] < 0.1 ? "met" : "NOT met")
     << "). Over all evaluated pixels (plate included) the compensated RMS is "
     << fmt(m["compensated_rms_mm"], 3) << " / " << fmt(m["accelerating_compensated_rms_mm"], 3)
     << " mm with the few gross (period) errors, " << fmt(m["compensated_inlier_rms_mm"], 4)
     << " / " << fmt(m["accelerating_compensated_inlier_rms_mm"], 4)
     << " mm without.\n\nErrors against the ground truth at image " << reference
     << " (the compensation's reference), over pixels more than 30 px from depth "
     << "steps; cross-section at image row " << section_row << ".\n";
  result.markdown = md.str();

  if (!options.out_dir.empty()) {
    std::vector<Curve> curves;
    auto section = [&](const cv::Mat& depth, const std::string& label, cv::Scalar colour) {
      Curve curve{label, {}, {}, colour};
      for (int c = 40; c < depth.cols - 40; ++c) {
        curve.x.push_back(c);
        curve.y.push_back(depth.at<float>(section_row, c));
      }
      curves.push_back(curve);
    };
    section(gt_moving, "ground truth (image " + std::to_string(reference) + ")",
            cv::Scalar(0, 0, 0));
    section(conditions[1].first_depth, "no compensation", cv::Scalar(0, 0, 220));
    section(conditions[2].first_depth, "motion compensation (defaults)", cv::Scalar(200, 80, 0));
    section(conditions[3].first_depth, "motion compensation (window: false)",
            cv::Scalar(0, 160, 0));
    const std::string path = plotPath(options, "motion_cross_section.png");
    writeLinePlot(path, curves,
                  "Depth cross-section, image row " + std::to_string(section_row) +
                      ", sensor moving 2 mm/image",
                  "image column / px", "depth z / mm");
    result.plots.push_back(path);
    curves.clear();
    section(gt_accelerating, "ground truth (image " + std::to_string(reference) + ")",
            cv::Scalar(0, 0, 0));
    section(conditions[4].first_depth, "no compensation", cv::Scalar(0, 0, 220));
    section(conditions[5].first_depth, "motion compensation (defaults)", cv::Scalar(200, 80, 0));
    const std::string accelerating_path =
        plotPath(options, "motion_accelerating_cross_section.png");
    writeLinePlot(accelerating_path, curves,
                  "Depth cross-section, image row " + std::to_string(section_row) +
                      ", sensor accelerating from 1 to 3 mm/image",
                  "image column / px", "depth z / mm");
    result.plots.push_back(accelerating_path);
  }
  return result;
}

namespace {

// A cone by apex, unit axis (apex -> base) and half-angle; the signed distance
// of a point to its (infinite) surface is r cos(theta) - h sin(theta).
struct ConeModel {
  Eigen::Vector3d apex;
  Eigen::Vector3d axis;
  double half_angle;
};

double coneDistance(const ConeModel& c, const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = p - c.apex;
  const double h = q.dot(c.axis);
  const double r = (q - h * c.axis).norm();
  return r * std::cos(c.half_angle) - h * std::sin(c.half_angle);
}

// Parameters: apex (3), axis tilt (2, about two axes perpendicular to the
// initial axis), half-angle (1).
ConeModel coneFromParameters(const ConeModel& initial, const Eigen::Matrix<double, 6, 1>& x) {
  Eigen::Vector3d e1 = initial.axis.unitOrthogonal();
  Eigen::Vector3d e2 = initial.axis.cross(e1);
  ConeModel c;
  c.apex = initial.apex + x.head<3>();
  c.axis = (initial.axis + x[3] * e1 + x[4] * e2).normalized();
  c.half_angle = initial.half_angle + x[5];
  return c;
}

// Levenberg-Marquardt on the point-to-surface distances (numeric Jacobian).
ConeModel fitCone(const ConeModel& initial, const std::vector<Eigen::Vector3d>& points) {
  Eigen::Matrix<double, 6, 1> x = Eigen::Matrix<double, 6, 1>::Zero();
  auto residuals = [&](const Eigen::Matrix<double, 6, 1>& params) {
    const ConeModel c = coneFromParameters(initial, params);
    Eigen::VectorXd r(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) r[i] = coneDistance(c, points[i]);
    return r;
  };
  Eigen::VectorXd r = residuals(x);
  double lambda = 1e-3;
  for (int iteration = 0; iteration < 50; ++iteration) {
    Eigen::MatrixXd J(points.size(), 6);
    for (int k = 0; k < 6; ++k) {
      Eigen::Matrix<double, 6, 1> step = x;
      const double h = k < 3 ? 1e-4 : 1e-6;
      step[k] += h;
      J.col(k) = (residuals(step) - r) / h;
    }
    const Eigen::Matrix<double, 6, 6> JtJ = J.transpose() * J;
    const Eigen::Matrix<double, 6, 1> g = J.transpose() * r;
    Eigen::Matrix<double, 6, 6> A = JtJ;
    A.diagonal() *= (1 + lambda);
    const Eigen::Matrix<double, 6, 1> dx = A.ldlt().solve(-g);
    const Eigen::VectorXd r_new = residuals(x + dx);
    if (r_new.squaredNorm() < r.squaredNorm()) {
      x += dx;
      r = r_new;
      lambda *= 0.3;
      if (dx.norm() < 1e-9) break;
    } else {
      lambda *= 10;
    }
  }
  return coneFromParameters(initial, x);
}

}  // namespace

EvalResult runCones(const EvalOptions& requested) {
  const EvalOptions options = withDefaultScans(requested, "cones");
  if (options.scans < 1) throw std::invalid_argument("cones: needs at least 1 scan");
  // Top camera 150 mm above the projector (vertical 3+3, rows); left camera
  // 150 mm left of it (horizontal 3+3, columns); both calibrated against it.
  const pipeline::CameraProjectorCalibration top = rig({0, 150, 0}, 520);
  const pipeline::CameraProjectorCalibration left = rig({150, 0, 0}, 520);
  const pipeline::PatternSpec vertical = pattern33("3+3_vertical", pipeline::Direction::kVertical);
  const pipeline::PatternSpec horizontal =
      pattern33("3+3_horizontal", pipeline::Direction::kHorizontal);
  drivers::SimConfig config = baseConfig(top, vertical, options);
  config.patterns = {vertical, horizontal};
  config.second_camera = drivers::SimCamera{"sim_left", left};
  // The evaluation board: 6 cones (base radius 15 mm, height 20 mm) on a plate at 520 mm.
  config.scene.planes = {drivers::SimPlane{{0, 0, 520}, {0, 0, -1}, 0.8}};
  const double cone_radius = 15, cone_height = 20;
  for (double y : {-45.0, 45.0})
    for (double x : {-80.0, 0.0, 80.0})
      config.scene.cones.push_back(
          drivers::SimCone{{x, y, 520}, {0, 0, -1}, cone_radius, cone_height, 0.8});
  const auto sensor = drivers::SimulatedSensor::create(config);
  const std::size_t cone_count = config.scene.cones.size();
  std::vector<Eigen::Vector3d> true_apex;
  for (const drivers::SimCone& c : config.scene.cones)
    true_apex.push_back(c.base_center + c.height * c.axis.normalized());

  struct CameraSetup {
    std::string name;
    const pipeline::CameraProjectorCalibration* rig;
    const pipeline::PatternSpec* pattern;
    pipeline::TriangulatorOptions::Use use;
  };
  const std::vector<CameraSetup> setups = {
      {"top", &top, &vertical, pipeline::TriangulatorOptions::Use::kRows},
      {"left", &left, &horizontal, pipeline::TriangulatorOptions::Use::kColumns}};
  EvalResult result;
  std::ostringstream md;
  md << "### Cones: 6 cones (r 15 mm, h 20 mm) on a plate at 520 mm, " << options.scans
     << " scan(s) per camera; apex distances from cone 1\n\n"
     << "| distance | truth / mm | top: RMSE / mm | top: std / mm | left: RMSE / mm | left: std / "
        "mm |\n|---|---|---|---|---|---|\n";
  // errors[camera][k][scan]
  std::vector<std::vector<std::vector<double>>> errors(
      setups.size(), std::vector<std::vector<double>>(cone_count));
  // Mean signed distance of the segmented points to the true cone (+ outside).
  std::vector<double> deviation_sum(setups.size(), 0.0);
  std::vector<long long> deviation_count(setups.size(), 0);
  for (std::size_t cam = 0; cam < setups.size(); ++cam) {
    const CameraSetup& setup = setups[cam];
    const pipeline::Decoder decoder(*setup.pattern, pipeline::DecoderOptions{});
    pipeline::TriangulatorOptions t;
    t.use = setup.use;
    t.min_depth_mm = 200;
    t.max_depth_mm = 1500;
    const pipeline::Triangulator triangulator(*setup.rig, t);
    const Eigen::Isometry3d to_first = pipeline::cameraToCamera(*setup.rig, top);
    const Eigen::Isometry3d from_first = to_first.inverse();
    for (int k = 0; k < options.scans; ++k) {
      std::vector<cv::Mat> images;
      for (int i = 0; i < setup.pattern->frameCount(); ++i)
        images.push_back(sensor->render(static_cast<int>(cam), setup.pattern->name, i,
                                        (300 + k) * 1000 + i + 1 + cam * 100));
      const pipeline::PointCloud cloud = triangulator.triangulate(decoder.decode(images, 8));
      std::vector<Eigen::Vector3d> fitted;
      for (std::size_t j = 0; j < cone_count; ++j) {
        // Segmentation by the true cone (as by hand on a real board), away from the
        // base crease: points within 2 mm of the surface, 1..18.5 mm below the apex.
        ConeModel truth{from_first * true_apex[j],
                        from_first.linear() * -config.scene.cones[j].axis.normalized(),
                        std::atan(cone_radius / cone_height)};
        std::vector<Eigen::Vector3d> points;
        for (const pipeline::PointXYZI& p : cloud.points) {
          if (std::isnan(p.z)) continue;
          const Eigen::Vector3d x(p.x, p.y, p.z);
          const double h = (x - truth.apex).dot(truth.axis);
          if (h < 1.0 || h > cone_height - 1.5) continue;
          const double deviation = coneDistance(truth, x);
          if (std::abs(deviation) > 2.0) continue;
          points.push_back(x);
          deviation_sum[cam] += deviation;
          ++deviation_count[cam];
        }
        if (points.size() < 50) {
          fitted.push_back(Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN()));
          continue;
        }
        // Thin to <= 4000 points (every n-th) and start 1 mm / 2 deg off the truth.
        const std::size_t stride = std::max<std::size_t>(1, points.size() / 4000);
        std::vector<Eigen::Vector3d> used;
        for (std::size_t i = 0; i < points.size(); i += stride) used.push_back(points[i]);
        ConeModel start = truth;
        start.apex += Eigen::Vector3d(1, -1, 1);
        start.half_angle += radiansOf(2.0);
        fitted.push_back(to_first * fitCone(start, used).apex);
      }
      for (std::size_t j = 1; j < cone_count; ++j)
        errors[cam][j].push_back((fitted[j] - fitted[0]).norm() -
                                 (true_apex[j] - true_apex[0]).norm());
    }
  }
  auto stats = [](const std::vector<double>& e) {
    double sum = 0, sq = 0;
    int n = 0;
    for (double v : e)
      if (!std::isnan(v)) sum += v, sq += v * v, ++n;
    const double mean = n ? sum / n : std::numeric_limits<double>::quiet_NaN();
    const double rmse = n ? std::sqrt(sq / n) : mean;
    const double var = n > 1 ? std::max(0.0, (sq - n * mean * mean) / (n - 1)) : 0.0;
    return std::pair(rmse, std::sqrt(var));
  };
  double worst = 0;
  for (std::size_t j = 1; j < cone_count; ++j) {
    md << "| 1 -> " << j + 1 << " | " << fmt((true_apex[j] - true_apex[0]).norm(), 2);
    for (std::size_t cam = 0; cam < setups.size(); ++cam) {
      const auto [rmse, sd] = stats(errors[cam][j]);
      md << " | " << fmt(rmse, 3) << " | " << fmt(sd, 3);
      result.metrics[setups[cam].name + "_rmse_1_" + std::to_string(j + 1) + "_mm"] = rmse;
      worst = std::isnan(rmse) ? std::numeric_limits<double>::infinity() : std::max(worst, rmse);
    }
    md << " |\n";
  }
  result.metrics["worst_rmse_mm"] = worst;
  md << "| mean error (systematic) |";
  for (std::size_t cam = 0; cam < setups.size(); ++cam) {
    double sum = 0;
    int count = 0;
    for (std::size_t j = 1; j < cone_count; ++j)
      for (double e : errors[cam][j])
        if (!std::isnan(e)) sum += e, ++count;
    const double mean = count ? sum / count : std::numeric_limits<double>::quiet_NaN();
    const double deviation =
        deviation_sum[cam] / double(std::max<long long>(deviation_count[cam], 1));
    result.metrics[setups[cam].name + "_distance_mean_error_mm"] = mean;
    result.metrics[setups[cam].name + "_surface_mean_deviation_mm"] = deviation;
    md << " | " << fmt(mean, 4) << " |";
  }
  md << " |\n";
  md << "\nSystematic errors: mean signed distance error over all distances and scans (last "
        "row); mean signed distance of the segmented points to the true cones (+ outside): top "
     << fmt(result.metrics["top_surface_mean_deviation_mm"], 4) << " mm, left "
     << fmt(result.metrics["left_surface_mean_deviation_mm"], 4) << " mm"
     << (options.projector_gamma != 1.0
             ? "; projector gamma " + fmt(options.projector_gamma, 2) + "."
             : ".")
     << "\n";
  md << "\nCone fit: Levenberg-Marquardt on point-to-surface distances (apex, axis, half-angle), "
        "points segmented with the true cone. Paper (real sensor): RMSE 0.08-0.71 mm (top), "
        "0.33-1.14 mm (left).\n";
  result.markdown = md.str();
  return result;
}

namespace {

// Empirical standard deviation of the orthogonal distances to the best-fit plane.
double planeEsd(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 10) return std::numeric_limits<double>::quiet_NaN();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) mean += p;
  mean /= double(points.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : points) covariance += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  const Eigen::Vector3d normal = solver.eigenvectors().col(0);  // smallest eigenvalue
  double sq = 0;
  for (const Eigen::Vector3d& p : points) sq += std::pow((p - mean).dot(normal), 2);
  return std::sqrt(sq / double(points.size() - 1));
}

}  // namespace

EvalResult runRoughness(const EvalOptions& requested) {
  const EvalOptions options = withDefaultScans(requested, "roughness");
  const pipeline::CameraProjectorCalibration calibration = rig({150, 0, 0}, 550);
  const pipeline::PatternSpec spec = pattern33("3+3_horizontal", pipeline::Direction::kHorizontal);
  const pipeline::Decoder decoder(spec, pipeline::DecoderOptions{});
  pipeline::TriangulatorOptions t;
  t.use = pipeline::TriangulatorOptions::Use::kColumns;
  t.min_depth_mm = 200;
  t.max_depth_mm = 1500;
  const pipeline::Triangulator triangulator(calibration, t);
  // Four 17 x 17 cm plaster-like samples at 500 mm whose ESD on the patch is
  // the paper's reference (GOM ATOS) ESD.
  const std::vector<double> target = {0.008, 0.026, 0.053, 0.146};
  const std::vector<double> paper_sl = {0.076, 0.080, 0.099, 0.155};
  const double half_patch = 0.5 * std::sqrt(3000.0);  // 30 cm^2 square patch, mm
  const int n = options.scans;
  EvalResult result;
  auto& m = result.metrics;
  std::ostringstream md;
  md << "### Roughness: 17 x 17 cm samples at 500 mm, ESD (std of the orthogonal distances to "
        "the best-fit plane) over a 30 cm^2 patch, "
     << n << " scan(s)\n\n"
     << "| sample | ESD, truth (the surface on the patch) / mm | truth at the camera's pixels "
        "/ mm | single scan (mean over "
     << n << ") / mm | error / mm | mean of the " << n
     << " scans / mm | error / mm | paper: GOM / SL Sensor / mm |\n"
        "|---|---|---|---|---|---|---|---|\n";
  std::vector<double> truth_esd, single_esd, averaged_esd;
  for (std::size_t i = 0; i < target.size(); ++i) {
    std::string sample = "S";  // (not "S" + ...: GCC 12 warns falsely on that)
    sample += std::to_string(i + 1);
    drivers::SimConfig config = baseConfig(calibration, spec, options);
    drivers::SimHeightField field;
    field.origin = {0, 0, 500};
    field.width_mm = 170;
    field.length_mm = 170;
    field.cell_mm = 0.25;
    field.roughness = drivers::SimRoughness{target[i], 2.0, 0.8, 11 + i};
    // Generate the field, then scale it so that the ESD of the surface it
    // describes (bilinear between the samples, as the simulator renders it)
    // on the patch is the target. That ESD is taken on 4 x 4 points per cell;
    // the samples' own ESD is ~9 % higher, because bilinear interpolation
    // smooths the roughness finer than a cell. Orthogonal regression is not
    // exactly linear in the scale: a few rounds converge.
    config.scene.height_fields = {field};
    field.heights_mm = drivers::SimulatedSensor::create(config)
                           ->config()
                           .scene.height_fields[0]
                           .heights_mm.clone();
    field.roughness.reset();
    auto patchEsd = [&](const cv::Mat& heights) {
      constexpr int kSub = 4;
      std::vector<Eigen::Vector3d> points;
      for (int r = 0; r + 1 < heights.rows; ++r)
        for (int c = 0; c + 1 < heights.cols; ++c)
          for (int sy = 0; sy < kSub; ++sy)
            for (int sx = 0; sx < kSub; ++sx) {
              const double fx = (sx + 0.5) / kSub, fy = (sy + 0.5) / kSub;
              const double x = -0.5 * field.width_mm + (c + fx) * field.cell_mm;
              const double y = -0.5 * field.length_mm + (r + fy) * field.cell_mm;
              if (std::abs(x) >= half_patch || std::abs(y) >= half_patch) continue;
              const double h = (1 - fy) * ((1 - fx) * heights.at<float>(r, c) +
                                           fx * heights.at<float>(r, c + 1)) +
                               fy * ((1 - fx) * heights.at<float>(r + 1, c) +
                                     fx * heights.at<float>(r + 1, c + 1));
              points.emplace_back(x, y, h);
            }
      return planeEsd(points);
    };
    for (int round = 0; round < 4; ++round)
      field.heights_mm *= target[i] / patchEsd(field.heights_mm);
    const double esd_truth = patchEsd(field.heights_mm);
    config.scene.height_fields = {field};
    const auto sensor = drivers::SimulatedSensor::create(config);
    const cv::Mat& gt = sensor->groundTruth().xyz_mm;
    auto inPatch = [&](int r, int c) {
      const cv::Vec3f p = gt.at<cv::Vec3f>(r, c);
      return !std::isnan(p[2]) && std::abs(p[0]) < half_patch && std::abs(p[1]) < half_patch;
    };
    std::vector<Eigen::Vector3d> truth_at_pixels;
    for (int r = 0; r < gt.rows; ++r)
      for (int c = 0; c < gt.cols; ++c)
        if (inPatch(r, c)) {
          const cv::Vec3f p = gt.at<cv::Vec3f>(r, c);
          truth_at_pixels.emplace_back(p[0], p[1], p[2]);
        }
    // Per scan ESD, and the per-pixel mean point over the scans.
    double single_sum = 0;
    cv::Mat sum(gt.size(), CV_64FC3, cv::Scalar::all(0));
    cv::Mat count(gt.size(), CV_32SC1, cv::Scalar(0));
    for (int k = 0; k < n; ++k) {
      const pipeline::PointCloud cloud = triangulator.triangulate(
          decoder.decode(renderScan(*sensor, spec.name, spec.frameCount(), 400 + k), 8));
      std::vector<Eigen::Vector3d> points;
      for (int r = 0; r < cloud.height; ++r)
        for (int c = 0; c < cloud.width; ++c) {
          const pipeline::PointXYZI& p =
              cloud.points[static_cast<std::size_t>(r) * cloud.width + c];
          if (std::isnan(p.z) || !inPatch(r, c)) continue;
          points.emplace_back(p.x, p.y, p.z);
          sum.at<cv::Vec3d>(r, c) += cv::Vec3d(p.x, p.y, p.z);
          ++count.at<int>(r, c);
        }
      single_sum += planeEsd(points);
    }
    std::vector<Eigen::Vector3d> averaged;
    for (int r = 0; r < gt.rows; ++r)
      for (int c = 0; c < gt.cols; ++c)
        if (count.at<int>(r, c) == n) {
          const cv::Vec3d p = sum.at<cv::Vec3d>(r, c) / n;
          averaged.emplace_back(p[0], p[1], p[2]);
        }
    const double esd_single = single_sum / n, esd_averaged = planeEsd(averaged);
    truth_esd.push_back(esd_truth);
    single_esd.push_back(esd_single);
    averaged_esd.push_back(esd_averaged);
    m[sample + "_esd_truth_mm"] = esd_truth;
    m[sample + "_esd_truth_pixels_mm"] = planeEsd(truth_at_pixels);
    m[sample + "_esd_mm"] = esd_single;
    m[sample + "_esd_error_mm"] = esd_single - esd_truth;
    m[sample + "_esd_averaged_mm"] = esd_averaged;
    m[sample + "_esd_averaged_error_mm"] = esd_averaged - esd_truth;
    md << "| " << sample << " | " << fmt(esd_truth, 4) << " | "
       << fmt(m[sample + "_esd_truth_pixels_mm"], 4) << " | " << fmt(esd_single, 4) << " | "
       << fmt(esd_single - esd_truth, 4) << " | " << fmt(esd_averaged, 4) << " | "
       << fmt(esd_averaged - esd_truth, 4) << " | " << fmt(target[i], 3) << " / "
       << fmt(paper_sl[i], 3) << " |\n";
  }
  auto ranked = [&](const std::vector<double>& esd) {
    for (std::size_t i = 1; i < esd.size(); ++i)
      if (!(esd[i] > esd[i - 1])) return 0.0;
    return 1.0;
  };
  m["ranked_correctly"] = ranked(single_esd);
  m["ranked_correctly_averaged"] = ranked(averaged_esd);
  auto within = [&](const std::string& key) {
    std::string verdict;
    for (const char* sample : {"S3", "S4"}) {
      const double error = m[sample + key];
      verdict += std::string(verdict.empty() ? "" : ", ") + sample + " " +
                 (std::abs(error) < 0.02 ? "met" : "NOT met") + " (" + fmt(error, 3) + ")";
    }
    return verdict;
  };
  // The sensor's depth noise on the patch: what single scans add in quadrature.
  m["noise_esd_mm"] =
      std::sqrt(std::max(0.0, single_esd[0] * single_esd[0] - truth_esd[0] * truth_esd[0]));
  md << "\nSingle-scan ESD is about sqrt(truth^2 + noise^2) with the sensor's depth noise ("
     << fmt(m["noise_esd_mm"], 3)
     << " mm here, see precision), so a single scan overstates smooth samples. Averaging the "
        "scans of a static sample point by point (normal practice for roughness) divides the "
        "noise by sqrt("
     << n << "). Ranking: " << (m["ranked_correctly"] > 0 ? "correct" : "WRONG")
     << " from single scans, " << (m["ranked_correctly_averaged"] > 0 ? "correct" : "WRONG")
     << " from the mean. Issue 3's target, S3 and S4 within 0.02 mm of the truth: "
     << within("_esd_error_mm") << " from single scans, " << within("_esd_averaged_error_mm")
     << " from the mean of the scans.\n";
  result.markdown = md.str();
  return result;
}

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

std::vector<std::string> experimentNames() {
  return {"precision", "cones", "roughness", "motion", "vdi2634", "gamma", "wall"};
}

int defaultScans(const std::string& name) {
  if (name == "vdi2634") return 1;  // the guideline measures each pose once
  if (name == "wall") return 21;    // horizontal pass: 25 mm apart
  return 10;                        // the paper's 10 consecutive scans
}

EvalResult runExperiment(const std::string& name, const EvalOptions& options) {
  if (name == "precision") return runPrecision(options);
  if (name == "motion") return runMotion(options);
  if (name == "cones") return runCones(options);
  if (name == "roughness") return runRoughness(options);
  if (name == "vdi2634") return runVdi2634(options);
  if (name == "gamma") return runGamma(options);
  if (name == "wall") return runWall(options);
  std::string known;
  for (const std::string& n : experimentNames()) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown experiment '" + name + "' (known: " + known + ")");
}

}  // namespace sl::eval
