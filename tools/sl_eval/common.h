// Pieces shared by sl_eval's experiments: the simulated rig of
// config/sim.yaml, rendering a scan, the noise model's prediction of the
// decoded projector coordinate's noise, geometric fits and formatting.
// Private to sl_eval; free functions, no state.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <limits>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "eval.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/triangulator.h"
#include "sl/pipeline/types.h"

namespace sl::eval {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr double kFps = 30.0;
// High-frequency periods of the 3+3 patterns, as in config/sim.yaml.
constexpr int kFringes = 40;

// The camera and projector of config/sim.yaml (drivers::simRig()), with the
// projector at projector_center (camera frame, mm), turned so the optical
// axes cross at (0, 0, cross_mm).
pipeline::CameraProjectorCalibration rig(const Eigen::Vector3d& projector_center, double cross_mm);

// SimConfig's radiometry (= config/sim.yaml) on the given rig and pattern,
// with the options' projector gamma.
drivers::SimConfig baseConfig(const pipeline::CameraProjectorCalibration& rig,
                              const pipeline::PatternSpec& pattern, const EvalOptions& options);

pipeline::PatternSpec pattern33(const std::string& name, pipeline::Direction direction);

// The experiments' triangulation: `use` (columns for a horizontal baseline,
// rows for a vertical one), depths 200..1500 mm.
pipeline::TriangulatorOptions evalTriangulation(pipeline::TriangulatorOptions::Use use);

// The frames of one sequence of the first camera, noise seeded from `seed`.
std::vector<cv::Mat> renderScan(const drivers::SimulatedSensor& sensor, const std::string& pattern,
                                int frames, std::uint64_t seed);

cv::Mat depthOf(const pipeline::PointCloud& cloud);  // CV_32FC1 z (mm), NaN invalid

// Standard deviation of the decoded projector coordinate (projector px) per
// pixel, from the camera noise model: sigma_I^2 = gain * A + read^2 + q^2/12
// (q = one 8-bit DN step scaled to the bit depth), sigma_phi = sqrt(2/N)
// sigma_I / B, sigma_u = sigma_phi * period / (2 pi). A and B are the maps'
// offset and modulation (8-bit DN). CV_32FC1, NaN where B is.
cv::Mat phaseNoiseFloor(const pipeline::ProjectorMaps& maps, const drivers::SimConfig& config,
                        const pipeline::PatternSpec& spec, bool columns);

// `options` with scans set to defaultScans(experiment) when <= 0.
EvalOptions withDefaultScans(const EvalOptions& options, const std::string& experiment);

double radiansOf(double degrees);
double percentile(std::vector<double> v, double q);  // q in [0, 1]
std::string fmt(double v, int decimals = 3);
std::string plotPath(const EvalOptions& options, const std::string& name);

// Least-squares fits (orthogonal distances).
struct SphereFit {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double radius = 0;
  double radius_std = 0;                                        // from the fit's covariance (mm)
  Eigen::Matrix3d center_covariance = Eigen::Matrix3d::Zero();  // mm^2
};
// Algebraic start, then Gauss-Newton on |p - c| - r. Needs >= 4 points.
SphereFit fitSphere(const std::vector<Eigen::Vector3d>& points);

struct PlaneFit {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();    // centroid
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit
};
PlaneFit fitPlane(const std::vector<Eigen::Vector3d>& points);

// Range (max - min) of the values, and the range left after dropping the
// fraction `drop` of them that lie farthest from their median (as VDI/VDE
// 2634 lets a probing or flatness test discard 0.3 % of the points).
double range(const std::vector<double>& values);
double rangeWithout(const std::vector<double>& values, double drop);
// The largest distance from the median (returned in *median) that a value may
// have and stay when the fraction `drop` of the values is discarded.
double discardThreshold(const std::vector<double>& values, double drop, double* median);

}  // namespace sl::eval
