// Board observations for the metrology tests: a checkerboard at a known pose
// in the camera frame, observed either through the full simulator chain
// (render the 3+3 both-direction scan, decode, detect corners, local
// homographies: the observations sl_calibrate makes) or by projecting its
// corners through the rig with Gaussian noise of the size that chain shows
// (test_calibration "simulator round trip": camera ~0.1 px, projector
// ~0.15 px RMS).
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <numbers>
#include <random>
#include <string>

#include "sl/drivers/sim.h"
#include "sl/pipeline/calibration.h"
#include "sl/pipeline/pattern.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/decoder.h"

namespace metrology_test {

inline double radians(double degrees) { return degrees * std::numbers::pi / 180.0; }
inline double degrees(double radians) { return radians * 180.0 / std::numbers::pi; }

struct BoardPose {
  double tilt_x_deg, tilt_y_deg, spin_deg;  // R = Rx * Ry * Rz of the board
  Eigen::Vector3d centre_mm;                // board centre, camera frame
};

// camera_from_board: the board frame (origin at the first inner corner, x
// along a row, z away from the camera) of `pose`.
inline Eigen::Isometry3d cameraFromBoard(const sl::pipeline::Checkerboard& board,
                                         const BoardPose& pose) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = (Eigen::AngleAxisd(radians(pose.tilt_x_deg), Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(radians(pose.tilt_y_deg), Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(radians(pose.spin_deg), Eigen::Vector3d::UnitZ()))
                   .toRotationMatrix();
  T.translation() = pose.centre_mm - 0.5 * board.square_mm *
                                         ((board.cols - 1) * T.linear().col(0) +
                                          (board.rows - 1) * T.linear().col(1));
  return T;
}

// The simulator plane carrying `board` at camera_from_board.
inline sl::drivers::SimPlane boardPlane(const sl::pipeline::Checkerboard& board,
                                        const Eigen::Isometry3d& camera_from_board) {
  sl::drivers::SimCheckerboard texture;
  texture.cols = board.cols;
  texture.rows = board.rows;
  texture.square_mm = board.square_mm;
  texture.x_axis = camera_from_board.linear().col(0);
  texture.y_axis = camera_from_board.linear().col(1);
  texture.origin = camera_from_board.translation();
  texture.dark_albedo = 0.25;
  texture.light_albedo = 0.85;
  sl::drivers::SimPlane plane;
  plane.point = camera_from_board.translation();
  plane.normal = -camera_from_board.linear().col(2);
  plane.albedo = 0.85;
  plane.checkerboard = texture;
  return plane;
}

// Corners projected through `rig` (the true geometry) with Gaussian noise.
inline sl::pipeline::BoardView syntheticView(const sl::pipeline::CameraProjectorCalibration& rig,
                                             const sl::pipeline::Checkerboard& board,
                                             const Eigen::Isometry3d& camera_from_board,
                                             double sigma_camera_px, double sigma_projector_px,
                                             std::mt19937_64& rng, const std::string& label) {
  std::normal_distribution<double> camera(0, sigma_camera_px), projector(0, sigma_projector_px);
  sl::pipeline::BoardView v;
  v.label = label;
  for (int id = 0; id < board.cornerCount(); ++id) {
    const cv::Point3f b = board.corner(id);
    const Eigen::Vector3d X = camera_from_board * Eigen::Vector3d(b.x, b.y, b.z);
    const Eigen::Vector2d qc = rig.camera.project(X);
    const Eigen::Vector2d qp = rig.projector.project(rig.R * X + rig.t);
    v.corner_ids.push_back(id);
    v.camera_px.emplace_back(qc.x() + camera(rng), qc.y() + camera(rng));
    v.projector_px.emplace_back(qp.x() + projector(rng), qp.y() + projector(rng));
  }
  return v;
}

// The full chain on the simulator with `rig` as the true geometry. Returns
// a view without corners, and sets *error, when the board is not found.
inline sl::pipeline::BoardView renderedView(const sl::pipeline::CameraProjectorCalibration& rig,
                                            const sl::pipeline::Checkerboard& board,
                                            const Eigen::Isometry3d& camera_from_board,
                                            std::uint64_t seed, const std::string& label,
                                            std::string* error) {
  sl::pipeline::PhaseShift33Pattern pattern;
  pattern.name = "3+3_both";
  pattern.direction = sl::pipeline::Direction::kBoth;
  const sl::pipeline::PatternSpec spec = sl::pipeline::toSpec(pattern);
  sl::drivers::SimConfig config;
  config.rig = rig;
  config.patterns = {spec};
  config.scene.planes = {boardPlane(board, camera_from_board)};
  const auto sensor = sl::drivers::SimulatedSensor::create(config);
  std::vector<cv::Mat> frames;
  for (int f = 0; f < spec.frameCount(); ++f)
    frames.push_back(sensor->render(spec.name, f, 1000 * seed + f));
  const sl::pipeline::Decoder decoder(spec, {});
  const auto maps = decoder.decode(frames, 8);
  // As test_calibration's round trip: the simulator has no optical blur of
  // the edges; squares span ~60 px.
  sl::pipeline::CornerDetectionOptions corners;
  corners.presmooth_sigma_px = 1.0;
  sl::pipeline::LocalHomographyOptions homographies;
  homographies.window_radius_px = 25;
  const auto result = sl::pipeline::observeBoard(sl::pipeline::meanImage(frames), maps, board,
                                                 label, corners, homographies);
  if (!result.view) {
    if (error) *error = result.error;
    return {};
  }
  return *result.view;
}

}  // namespace metrology_test
