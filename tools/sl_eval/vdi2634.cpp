// vdi2634: an acceptance test in the spirit of VDI/VDE 2634 part 2 on the
// simulated sensor (see eval.h for the characteristics reported).
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <stdexcept>

#include "common.h"
#include "eval.h"
#include "plots.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/triangulator.h"

namespace sl::eval {

namespace {

// VDI/VDE 2634-2 lets the probing and flatness tests discard up to 0.3 % of
// the points.
constexpr double kDiscard = 0.003;
// Draws of the noise model per expected range (their median is reported).
constexpr int kNoiseDraws = 9;

// One decoded and triangulated scan, with the noise model's prediction per
// pixel: the point moves along its camera ray by `ray_per_px` (mm per
// projector px) when the decoded column changes, and the decoded column's
// noise is sigma_up (projector px).
struct Scan {
  pipeline::PointCloud cloud;
  cv::Mat ray_per_px;  // CV_32FC3
  cv::Mat sigma_up;    // CV_32FC1
};

// The "left" camera of config/sim.yaml: projector 150 mm to the right, axes
// crossing at 550 mm, horizontal 3+3 (projector columns).
class Scanner {
 public:
  explicit Scanner(const EvalOptions& options)
      : options_(options),
        calibration_(rig({150, 0, 0}, 550)),
        spec_(pattern33("3+3_horizontal", pipeline::Direction::kHorizontal)),
        decoder_(spec_, pipeline::DecoderOptions{}),
        triangulator_(calibration_,
                      evalTriangulation(pipeline::TriangulatorOptions::Use::kColumns)) {}

  drivers::SimConfig config(const drivers::SimScene& scene) const {
    drivers::SimConfig c = baseConfig(calibration_, spec_, options_);
    c.scene = scene;
    return c;
  }

  Scan scan(const drivers::SimulatedSensor& sensor, std::uint64_t seed) const {
    const pipeline::ProjectorMaps maps =
        decoder_.decode(renderScan(sensor, spec_.name, spec_.frameCount(), seed), 8);
    Scan s;
    s.cloud = triangulator_.triangulate(maps);
    pipeline::ProjectorMaps plus = maps, minus = maps;  // shared buffers: new up maps
    plus.up = cv::Mat(maps.up + 0.5);
    minus.up = cv::Mat(maps.up - 0.5);
    const pipeline::PointCloud p = triangulator_.triangulate(plus);
    const pipeline::PointCloud m = triangulator_.triangulate(minus);
    s.ray_per_px = cv::Mat(maps.up.size(), CV_32FC3);
    for (std::size_t i = 0; i < p.points.size(); ++i)
      s.ray_per_px.at<cv::Vec3f>(static_cast<int>(i)) = {p.points[i].x - m.points[i].x,
                                                         p.points[i].y - m.points[i].y,
                                                         p.points[i].z - m.points[i].z};
    s.sigma_up = phaseNoiseFloor(maps, sensor.config(), spec_, true);
    return s;
  }

 private:
  EvalOptions options_;
  pipeline::CameraProjectorCalibration calibration_;
  pipeline::PatternSpec spec_;
  pipeline::Decoder decoder_;
  pipeline::Triangulator triangulator_;
};

// Points of one feature: measured point, its pixel, and the noise model's
// standard deviation of its distance to the true surface (mm).
struct FeaturePoints {
  std::vector<Eigen::Vector3d> points;
  std::vector<cv::Point> pixels;
  std::vector<double> sigma;
};

// Pixels whose ground-truth point satisfies `on_feature` and whose measured
// point is valid. normal_at(gt point) is the true surface normal there.
template <typename OnFeature, typename NormalAt>
FeaturePoints collect(const Scan& scan, const cv::Mat& gt_xyz, OnFeature on_feature,
                      NormalAt normal_at) {
  FeaturePoints f;
  for (int r = 0; r < gt_xyz.rows; ++r)
    for (int c = 0; c < gt_xyz.cols; ++c) {
      const cv::Vec3f g = gt_xyz.at<cv::Vec3f>(r, c);
      if (std::isnan(g[2])) continue;
      const Eigen::Vector3d truth(g[0], g[1], g[2]);
      if (!on_feature(truth)) continue;
      const pipeline::PointXYZI& p =
          scan.cloud.points[static_cast<std::size_t>(r) * scan.cloud.width + c];
      const float sigma_up = scan.sigma_up.at<float>(r, c);
      if (std::isnan(p.z) || std::isnan(sigma_up)) continue;
      const cv::Vec3f ray = scan.ray_per_px.at<cv::Vec3f>(r, c);
      f.points.emplace_back(p.x, p.y, p.z);
      f.pixels.emplace_back(c, r);
      f.sigma.push_back(std::abs(normal_at(truth).dot(Eigen::Vector3d(ray[0], ray[1], ray[2]))) *
                        sigma_up);
    }
  return f;
}

// Range of the residuals (all, and without 0.3 %) that the noise model alone
// gives for these points: median over kNoiseDraws draws of independent
// Gaussian residuals with the points' predicted sigmas.
std::pair<double, double> expectedRanges(const std::vector<double>& sigma, std::mt19937_64& rng) {
  std::vector<double> all, trimmed, e(sigma.size());
  std::normal_distribution<double> normal;
  for (int d = 0; d < kNoiseDraws; ++d) {
    for (std::size_t i = 0; i < sigma.size(); ++i) e[i] = sigma[i] * normal(rng);
    all.push_back(range(e));
    trimmed.push_back(rangeWithout(e, kDiscard));
  }
  return {percentile(all, 0.5), percentile(trimmed, 0.5)};
}

double rms(const std::vector<double>& v) {
  double sq = 0;
  for (double x : v) sq += x * x;
  return v.empty() ? 0.0 : std::sqrt(sq / double(v.size()));
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? std::numeric_limits<double>::quiet_NaN() : s / double(v.size());
}

double maxAbs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

// Indices of the points left after discarding the fraction `drop` whose
// residuals lie farthest from the median residual.
std::vector<std::size_t> kept(const std::vector<double>& residuals, double drop) {
  double median = 0;
  const double threshold = discardThreshold(residuals, drop, &median);
  std::vector<std::size_t> indices;
  for (std::size_t i = 0; i < residuals.size(); ++i)
    if (std::abs(residuals[i] - median) <= threshold) indices.push_back(i);
  return indices;
}

template <typename T>
std::vector<T> subset(const std::vector<T>& v, const std::vector<std::size_t>& indices) {
  std::vector<T> out;
  out.reserve(indices.size());
  for (std::size_t i : indices) out.push_back(v[i]);
  return out;
}

// The points to discard are chosen from the residuals to the current fit,
// which gross errors pull off the surface at first: choose and refit this often.
constexpr int kDiscardRounds = 3;

// A residual this large is a period (unwrapping) error, not noise.
constexpr double kGrossMm = 1.0;

struct FormResult {
  std::size_t points = 0, gross = 0;                    // gross: |residual| > kGrossMm
  double form = 0, form_trimmed = 0;                    // mm
  double expected_form = 0, expected_form_trimmed = 0;  // mm, noise model
  double residual_rms = 0, expected_rms = 0;            // mm, over the kept points
  double deviation = 0;  // mean signed distance of the kept points to the true surface (mm)
  cv::Mat residual_map;  // CV_32FC1 residual per kept pixel (NaN elsewhere), for the plot
};

// residuals: of all points to the fit made on the `keep` points.
FormResult formOf(const FeaturePoints& f, const std::vector<double>& residuals,
                  const std::vector<std::size_t>& keep, const std::vector<double>& true_distances,
                  cv::Size image, std::mt19937_64& rng) {
  FormResult r;
  r.points = residuals.size();
  for (double e : residuals) r.gross += std::abs(e) > kGrossMm;
  r.form = range(residuals);
  const std::vector<double> trimmed = subset(residuals, keep);
  r.form_trimmed = range(trimmed);
  std::tie(r.expected_form, r.expected_form_trimmed) = expectedRanges(f.sigma, rng);
  r.residual_rms = rms(trimmed);
  r.expected_rms = rms(f.sigma);
  r.deviation = mean(subset(true_distances, keep));
  r.residual_map = cv::Mat(image, CV_32FC1, cv::Scalar(kNaN));
  for (std::size_t i : keep)
    r.residual_map.at<float>(f.pixels[i]) = static_cast<float>(residuals[i]);
  return r;
}

struct SphereResult {
  SphereFit fit;  // on the kept points
  FormResult form;
  double size_error = 0;  // fitted minus true diameter (mm)
};

// Fit on all points, then kDiscardRounds times: discard 0.3 % of all points
// by their residuals to the current fit and refit on the rest. P_F and P_S
// come from the last fit.
SphereResult measureSphere(const Scan& scan, const cv::Mat& gt_xyz,
                           const drivers::SimSphere& sphere, std::mt19937_64& rng) {
  const FeaturePoints f = collect(
      scan, gt_xyz,
      [&](const Eigen::Vector3d& p) {
        return std::abs((p - sphere.center).norm() - sphere.radius) < 0.01;
      },
      [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
        return (p - sphere.center).normalized();
      });
  if (f.points.size() < 100) throw std::runtime_error("vdi2634: sphere hardly visible");
  auto residualsTo = [&](const SphereFit& fit) {
    std::vector<double> residuals;
    for (const Eigen::Vector3d& p : f.points)
      residuals.push_back((p - fit.center).norm() - fit.radius);
    return residuals;
  };
  SphereResult s;
  s.fit = fitSphere(f.points);
  std::vector<std::size_t> keep;
  for (int round = 0; round < kDiscardRounds; ++round) {
    keep = kept(residualsTo(s.fit), kDiscard);
    s.fit = fitSphere(subset(f.points, keep));
  }
  std::vector<double> true_distances;
  for (const Eigen::Vector3d& p : f.points)
    true_distances.push_back((p - sphere.center).norm() - sphere.radius);
  s.form = formOf(f, residualsTo(s.fit), keep, true_distances, gt_xyz.size(), rng);
  s.size_error = 2 * (s.fit.radius - sphere.radius);
  return s;
}

// A plane pose: centre, and in-plane axes (unit); the normal e1 x e2 faces the sensor.
struct PlanePose {
  std::string label;
  Eigen::Vector3d center;
  Eigen::Matrix3d rotation;  // columns e1, e2, normal
};

FormResult measurePlane(const Scan& scan, const cv::Mat& gt_xyz, const PlanePose& pose,
                        double half_width, double half_height, std::mt19937_64& rng) {
  const Eigen::Vector3d e1 = pose.rotation.col(0), e2 = pose.rotation.col(1);
  const Eigen::Vector3d normal = pose.rotation.col(2);
  const FeaturePoints f = collect(
      scan, gt_xyz,
      [&](const Eigen::Vector3d& p) {
        const Eigen::Vector3d d = p - pose.center;
        return std::abs(d.dot(e1)) <= half_width && std::abs(d.dot(e2)) <= half_height &&
               std::abs(d.dot(normal)) < 0.01;
      },
      [&](const Eigen::Vector3d&) { return normal; });
  if (f.points.size() < 1000) throw std::runtime_error("vdi2634: plane hardly visible");
  auto residualsTo = [&](const PlaneFit& fit) {
    std::vector<double> residuals;
    for (const Eigen::Vector3d& p : f.points) residuals.push_back((p - fit.point).dot(fit.normal));
    return residuals;
  };
  PlaneFit fit = fitPlane(f.points);
  std::vector<std::size_t> keep;
  for (int round = 0; round < kDiscardRounds; ++round) {
    keep = kept(residualsTo(fit), kDiscard);
    fit = fitPlane(subset(f.points, keep));
  }
  std::vector<double> true_distances;
  for (const Eigen::Vector3d& p : f.points) true_distances.push_back((p - pose.center).dot(normal));
  return formOf(f, residualsTo(fit), keep, true_distances, gt_xyz.size(), rng);
}

std::string vec(const Eigen::Vector3d& v) {
  std::string s = "(";
  s += fmt(v.x(), 0) + ", " + fmt(v.y(), 0) + ", " + fmt(v.z(), 0) + ")";
  return s;
}

// The residual map cropped to its valid pixels (plus a margin).
cv::Mat cropped(const cv::Mat& map) {
  cv::Mat valid = map == map;  // NaN != NaN
  const cv::Rect box = cv::boundingRect(valid);
  const int margin = 10;
  const cv::Rect grown(box.x - margin, box.y - margin, box.width + 2 * margin,
                       box.height + 2 * margin);
  return map(grown & cv::Rect(0, 0, map.cols, map.rows)).clone();
}

}  // namespace

EvalResult runVdi2634(const EvalOptions& requested) {
  const EvalOptions options = withDefaultScans(requested, "vdi2634");
  const int scans = options.scans;
  const Scanner scanner(options);
  std::mt19937_64 rng(2634);
  EvalResult result;
  auto& m = result.metrics;
  std::ostringstream md;
  md << "### VDI/VDE 2634-2 style acceptance test: measuring volume 200 x 150 x 100 mm around "
        "(0, 0, 500) mm in the camera frame (L0 = 269 mm), \"left\" camera with the horizontal "
        "3+3, "
     << scans << " measurement(s) per pose"
     << (options.projector_gamma != 1.0 ? ", projector gamma " + fmt(options.projector_gamma, 2)
                                        : std::string())
     << "\n\n"
     << "Points are taken where the ground truth lies on the feature (as a sphere or plane is "
        "segmented by hand). Each feature is fitted, the 0.3 % of the points farthest from the "
        "median residual are discarded (as the guideline allows) and the feature is fitted again "
        "(three rounds, each choosing from all points); \"99.7 %\" statistics are over the kept "
        "points, \"all\" over all points to the last fit. Gross errors (|residual| > 1 mm) are "
        "period errors of the temporal unwrapping. \"Expected\": the same statistic for "
        "independent Gaussian residuals with each point's standard deviation from the camera "
        "noise model (sigma_phi = sqrt(2/N) sigma_I / B along the camera ray, projected on the "
        "true normal). Signed deviations: + means outside the true sphere / in front of the true "
        "plane.\n\n";

  // --- Probing error: sphere of 40 mm diameter at 7 positions ---------------
  const double sphere_radius = 20;
  const std::vector<Eigen::Vector3d> sphere_positions = {
      {0, 0, 500},   {-90, -65, 460}, {90, -65, 540}, {-90, 65, 540},
      {90, 65, 460}, {0, 0, 460},     {0, 0, 540}};
  std::vector<double> form, form_trimmed, form_ratio, form_trimmed_ratio, size, size_std,
      sphere_deviation;
  cv::Mat worst_sphere_map;
  std::size_t sphere_gross = 0, sphere_points = 0;
  double worst_sphere_form = -1;
  md << "#### Probing error, sphere D = " << fmt(2 * sphere_radius, 1)
     << " mm (form P_F: range of the radial residuals of a least-squares sphere; size P_S: "
        "fitted minus true diameter)\n\n"
     << "| # | centre / mm | points | gross errors (> 1 mm) | P_F all / mm | P_F 99.7 % / mm | "
        "expected all / 99.7 % / "
        "mm | residual RMS / expected / mm | P_S / mm | +-1 sigma(P_S) / mm | mean radial "
        "deviation / mm |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  int row = 0;
  for (std::size_t i = 0; i < sphere_positions.size(); ++i) {
    drivers::SimScene scene;
    scene.spheres = {drivers::SimSphere{sphere_positions[i], sphere_radius, 0.8}};
    const auto sensor = drivers::SimulatedSensor::create(scanner.config(scene));
    for (int k = 0; k < scans; ++k) {
      const Scan scan = scanner.scan(*sensor, 2634000 + 100 * i + k);
      const SphereResult s =
          measureSphere(scan, sensor->groundTruth().xyz_mm, scene.spheres[0], rng);
      form.push_back(s.form.form);
      form_trimmed.push_back(s.form.form_trimmed);
      form_ratio.push_back(s.form.form / s.form.expected_form);
      form_trimmed_ratio.push_back(s.form.form_trimmed / s.form.expected_form_trimmed);
      size.push_back(s.size_error);
      size_std.push_back(2 * s.fit.radius_std);
      sphere_deviation.push_back(s.form.deviation);
      sphere_gross += s.form.gross;
      sphere_points += s.form.points;
      if (s.form.form > worst_sphere_form) {
        worst_sphere_form = s.form.form;
        worst_sphere_map = cropped(s.form.residual_map);
      }
      md << "| " << ++row << " | " << vec(sphere_positions[i]) << " | " << s.form.points << " | "
         << s.form.gross << " | " << fmt(s.form.form) << " | " << fmt(s.form.form_trimmed) << " | "
         << fmt(s.form.expected_form) << " / " << fmt(s.form.expected_form_trimmed) << " | "
         << fmt(s.form.residual_rms, 4) << " / " << fmt(s.form.expected_rms, 4) << " | "
         << fmt(s.size_error, 4) << " | " << fmt(2 * s.fit.radius_std, 4) << " | "
         << fmt(s.form.deviation, 4) << " |\n";
    }
  }
  md << "| **max** | | | | **" << fmt(percentile(form, 1)) << "** | **"
     << fmt(percentile(form_trimmed, 1)) << "** | | | **" << fmt(maxAbs(size), 4)
     << "** (abs) | | |\n"
     << "| **mean (systematic)** | | | | | | | | **" << fmt(mean(size), 4) << "** | | **"
     << fmt(mean(sphere_deviation), 4) << "** |\n\n";
  m["sphere_form_max_mm"] = percentile(form, 1);
  m["sphere_form997_max_mm"] = percentile(form_trimmed, 1);
  m["sphere_form_ratio_max"] = percentile(form_ratio, 1);
  m["sphere_form997_ratio_max"] = percentile(form_trimmed_ratio, 1);
  m["sphere_size_max_abs_mm"] = maxAbs(size);
  m["sphere_size_sigma_max_mm"] = percentile(size_std, 1);
  m["sphere_size_mean_mm"] = mean(size);
  m["sphere_deviation_mean_mm"] = mean(sphere_deviation);
  m["sphere_gross_fraction"] =
      double(sphere_gross) / double(std::max<std::size_t>(sphere_points, 1));

  // --- Sphere spacing error: ball bar, 2 spheres D = 25 mm, 180 mm apart ----
  const double ball_radius = 12.5, bar_length = 180;
  const Eigen::Vector3d volume(200, 150, 100);
  const std::vector<std::pair<std::string, Eigen::Vector3d>> bar_poses = {
      {"along x", {1, 0, 0}},
      {"space diagonal + + +", volume},
      {"space diagonal + + -", volume.cwiseProduct(Eigen::Vector3d(1, 1, -1))},
      {"space diagonal + - +", volume.cwiseProduct(Eigen::Vector3d(1, -1, 1))},
      {"space diagonal - + +", volume.cwiseProduct(Eigen::Vector3d(-1, 1, 1))},
      {"face diagonal x y", {200, 150, 0}},
      {"face diagonal x -y", {200, -150, 0}}};
  std::vector<double> spacing, spacing_std;
  md << "#### Sphere spacing error, ball bar: 2 spheres D = " << fmt(2 * ball_radius, 1)
     << " mm, centres " << fmt(bar_length, 0)
     << " mm apart (= 0.67 L0), centred at (0, 0, 500) mm (S_D: measured minus true centre "
        "distance)\n\n"
     << "| # | pose | direction | points | S_D / mm | +-1 sigma(S_D) / mm | P_S sphere 1 / 2 / "
        "mm |\n|---|---|---|---|---|---|---|\n";
  row = 0;
  cv::Mat worst_bar_map;
  double worst_bar = -1;
  for (std::size_t i = 0; i < bar_poses.size(); ++i) {
    const Eigen::Vector3d direction = bar_poses[i].second.normalized();
    const Eigen::Vector3d center(0, 0, 500);
    drivers::SimScene scene;
    scene.spheres = {drivers::SimSphere{center - 0.5 * bar_length * direction, ball_radius, 0.8},
                     drivers::SimSphere{center + 0.5 * bar_length * direction, ball_radius, 0.8}};
    const auto sensor = drivers::SimulatedSensor::create(scanner.config(scene));
    for (int k = 0; k < scans; ++k) {
      const Scan scan = scanner.scan(*sensor, 2635000 + 100 * i + k);
      const cv::Mat& gt = sensor->groundTruth().xyz_mm;
      const SphereResult a = measureSphere(scan, gt, scene.spheres[0], rng);
      const SphereResult b = measureSphere(scan, gt, scene.spheres[1], rng);
      const Eigen::Vector3d d = b.fit.center - a.fit.center;
      const double error = d.norm() - bar_length;
      const Eigen::Vector3d u = d.normalized();
      const double sigma =
          std::sqrt(u.dot((a.fit.center_covariance + b.fit.center_covariance) * u));
      spacing.push_back(error);
      spacing_std.push_back(sigma);
      if (std::abs(error) > worst_bar) {
        worst_bar = std::abs(error);
        cv::Mat both = a.form.residual_map.clone();
        b.form.residual_map.copyTo(both, b.form.residual_map == b.form.residual_map);
        worst_bar_map = cropped(both);
      }
      md << "| " << ++row << " | " << bar_poses[i].first << " | "
         << "(" << fmt(direction.x(), 2) << ", " << fmt(direction.y(), 2) << ", "
         << fmt(direction.z(), 2) << ") | " << a.form.points << " + " << b.form.points << " ("
         << a.form.gross + b.form.gross << " gross) | " << fmt(error, 4) << " | " << fmt(sigma, 4)
         << " | " << fmt(a.size_error, 4) << " / " << fmt(b.size_error, 4) << " |\n";
    }
  }
  md << "| **max** | | | | **" << fmt(maxAbs(spacing), 4) << "** (abs) | | |\n"
     << "| **mean (systematic)** | | | | **" << fmt(mean(spacing), 4) << "** | | |\n\n";
  m["spacing_max_abs_mm"] = maxAbs(spacing);
  m["spacing_mean_mm"] = mean(spacing);
  m["spacing_sigma_max_mm"] = percentile(spacing_std, 1);

  // --- Flatness error: 200 x 150 mm of a plane at 7 poses --------------------
  const double half_width = 100, half_height = 75;
  auto tilted = [](const std::string& label, const Eigen::Vector3d& center,
                   const Eigen::Vector3d& axis, double degrees) {
    const Eigen::Matrix3d turn =
        Eigen::AngleAxisd(radiansOf(degrees), axis.normalized()).toRotationMatrix();
    PlanePose pose{label, center, Eigen::Matrix3d::Identity()};
    pose.rotation.col(0) = turn * Eigen::Vector3d::UnitX();
    pose.rotation.col(1) = turn * -Eigen::Vector3d::UnitY();
    pose.rotation.col(2) = turn * -Eigen::Vector3d::UnitZ();  // faces the sensor
    return pose;
  };
  const std::vector<PlanePose> plane_poses = {
      tilted("frontal, z 500", {0, 0, 500}, Eigen::Vector3d::UnitY(), 0),
      tilted("turned +25 deg about y", {0, 0, 500}, Eigen::Vector3d::UnitY(), 25),
      tilted("turned -25 deg about y", {0, 0, 500}, Eigen::Vector3d::UnitY(), -25),
      tilted("turned +25 deg about x", {0, 0, 500}, Eigen::Vector3d::UnitX(), 25),
      tilted("turned -25 deg about x", {0, 0, 500}, Eigen::Vector3d::UnitX(), -25),
      tilted("frontal, z 460", {0, 0, 460}, Eigen::Vector3d::UnitY(), 0),
      tilted("frontal, z 540", {0, 0, 540}, Eigen::Vector3d::UnitY(), 0)};
  std::vector<double> flatness, flatness_trimmed, flatness_ratio, flatness_trimmed_ratio,
      plane_deviation;
  cv::Mat worst_plane_map;
  std::size_t plane_gross = 0, plane_points = 0;
  double worst_flatness = -1;
  md << "#### Flatness error, " << fmt(2 * half_width, 0) << " x " << fmt(2 * half_height, 0)
     << " mm of a plane (F: range of the residuals to the least-squares plane)\n\n"
     << "| # | pose | points | gross errors (> 1 mm) | F all / mm | F 99.7 % / mm | expected all / "
        "99.7 % / mm | "
        "residual RMS / expected / mm | mean deviation from the true plane / mm "
        "|\n|---|---|---|---|---|---|---|---|---|\n";
  row = 0;
  for (std::size_t i = 0; i < plane_poses.size(); ++i) {
    const PlanePose& pose = plane_poses[i];
    drivers::SimScene scene;
    scene.planes = {drivers::SimPlane{pose.center, pose.rotation.col(2), 0.8}};
    const auto sensor = drivers::SimulatedSensor::create(scanner.config(scene));
    for (int k = 0; k < scans; ++k) {
      const Scan scan = scanner.scan(*sensor, 2636000 + 100 * i + k);
      const FormResult f =
          measurePlane(scan, sensor->groundTruth().xyz_mm, pose, half_width, half_height, rng);
      flatness.push_back(f.form);
      flatness_trimmed.push_back(f.form_trimmed);
      flatness_ratio.push_back(f.form / f.expected_form);
      flatness_trimmed_ratio.push_back(f.form_trimmed / f.expected_form_trimmed);
      plane_deviation.push_back(f.deviation);
      plane_gross += f.gross;
      plane_points += f.points;
      if (f.form > worst_flatness) {
        worst_flatness = f.form;
        worst_plane_map = cropped(f.residual_map);
      }
      md << "| " << ++row << " | " << pose.label << " | " << f.points << " | " << f.gross << " | "
         << fmt(f.form) << " | " << fmt(f.form_trimmed) << " | " << fmt(f.expected_form) << " / "
         << fmt(f.expected_form_trimmed) << " | " << fmt(f.residual_rms, 4) << " / "
         << fmt(f.expected_rms, 4) << " | " << fmt(f.deviation, 4) << " |\n";
    }
  }
  md << "| **max** | | | | **" << fmt(percentile(flatness, 1)) << "** | **"
     << fmt(percentile(flatness_trimmed, 1)) << "** | | | |\n"
     << "| **mean (systematic)** | | | | | | | | **" << fmt(mean(plane_deviation), 4) << "** |\n\n";
  m["flatness_max_mm"] = percentile(flatness, 1);
  m["flatness997_max_mm"] = percentile(flatness_trimmed, 1);
  m["flatness_ratio_max"] = percentile(flatness_ratio, 1);
  m["flatness997_ratio_max"] = percentile(flatness_trimmed_ratio, 1);
  m["plane_deviation_mean_mm"] = mean(plane_deviation);
  m["plane_gross_points"] = double(plane_gross);
  m["plane_gross_fraction"] = double(plane_gross) / double(std::max<std::size_t>(plane_points, 1));
  m["systematic_max_abs_mm"] =
      std::max({std::abs(m["sphere_size_mean_mm"]), std::abs(m["sphere_deviation_mean_mm"]),
                std::abs(m["spacing_mean_mm"]), std::abs(m["plane_deviation_mean_mm"])});

  md << "#### Summary\n\n| characteristic | max / mm | systematic (mean) / mm | max measured / "
        "expected from noise |\n|---|---|---|---|\n"
     << "| probing error form P_F (all / 99.7 %) | " << fmt(m["sphere_form_max_mm"]) << " / "
     << fmt(m["sphere_form997_max_mm"]) << " | | " << fmt(m["sphere_form_ratio_max"], 2) << " / "
     << fmt(m["sphere_form997_ratio_max"], 2) << " |\n"
     << "| probing error size P_S | " << fmt(m["sphere_size_max_abs_mm"], 4) << " | "
     << fmt(m["sphere_size_mean_mm"], 4) << " | |\n"
     << "| sphere spacing error S_D | " << fmt(m["spacing_max_abs_mm"], 4) << " | "
     << fmt(m["spacing_mean_mm"], 4) << " | |\n"
     << "| flatness error F (all / 99.7 %) | " << fmt(m["flatness_max_mm"]) << " / "
     << fmt(m["flatness997_max_mm"]) << " | " << fmt(m["plane_deviation_mean_mm"], 4)
     << " (points vs true plane) | " << fmt(m["flatness_ratio_max"], 2) << " / "
     << fmt(m["flatness997_ratio_max"], 2) << " |\n";
  result.markdown = md.str();

  if (!options.out_dir.empty()) {
    auto plot = [&](const std::string& name, const cv::Mat& map, const std::string& title) {
      std::vector<double> values;
      for (auto it = map.begin<float>(); it != map.end<float>(); ++it)
        if (!std::isnan(*it)) values.push_back(*it);
      const std::string path = plotPath(options, name);
      writeSignedMap(path, map, std::max(0.01, 4 * rms(values)), title, "mm");
      result.plots.push_back(path);
    };
    plot("vdi2634_sphere_residuals.png", worst_sphere_map,
         "Sphere: radial residuals, largest P_F (" + fmt(worst_sphere_form) + " mm)");
    plot("vdi2634_ball_bar_residuals.png", worst_bar_map,
         "Ball bar: radial residuals, largest |S_D| (" + fmt(worst_bar, 4) + " mm)");
    plot("vdi2634_plane_residuals.png", worst_plane_map,
         "Plane: residuals, largest F (" + fmt(worst_flatness) + " mm)");
  }
  return result;
}

}  // namespace sl::eval
