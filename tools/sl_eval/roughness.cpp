// 4.2 roughness (eval.h runRoughness): four rough samples scaled to the
// paper's reference ESDs, the sensor's ESD per scan and of the mean scan.
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "common.h"
#include "eval.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/triangulator.h"

namespace sl::eval {

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
  const pipeline::Triangulator triangulator(
      calibration, evalTriangulation(pipeline::TriangulatorOptions::Use::kColumns));
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

}  // namespace sl::eval
