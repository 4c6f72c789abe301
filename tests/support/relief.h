// Test support: a plaster-like relief as a height field, and the same
// samples as a triangle mesh (two triangles per cell), for tests and
// benchmarks that compare the simulator's height-field and mesh ray casting.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "sl/drivers/sim.h"

namespace sl::test {

// Gaussian-filtered white noise (sigma in cells) scaled to rms_mm.
inline cv::Mat smoothNoise(int rows, int cols, double sigma_cells, double rms_mm,
                           std::uint64_t seed) {
  cv::Mat noise(rows, cols, CV_32FC1);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0, 1);
  cv::Mat smooth;
  cv::GaussianBlur(noise, smooth, cv::Size(0, 0), sigma_cells, sigma_cells, cv::BORDER_REFLECT);
  cv::Scalar mean, stddev;
  cv::meanStdDev(smooth, mean, stddev);
  return (smooth - mean[0]) * (rms_mm / stddev[0]);
}

// A wall of width x length mm facing the camera (normal -z) at `distance`
// mm, 1 mm cells, with bumps of 1.2 mm RMS (12 mm correlation) and 0.05 mm
// roughness (1.5 mm), as sl_eval wall's plaster.
inline drivers::SimHeightField plasterWall(double width, double length, double distance,
                                           std::uint64_t seed = 41) {
  drivers::SimHeightField f;
  f.origin = Eigen::Vector3d(0, 0, distance);
  f.normal = Eigen::Vector3d(0, 0, -1);
  f.x_axis = Eigen::Vector3d(1, 0, 0);
  f.width_mm = width;
  f.length_mm = length;
  f.cell_mm = 1.0;
  const int rows = static_cast<int>(std::lround(length)) + 1;
  const int cols = static_cast<int>(std::lround(width)) + 1;
  f.heights_mm = smoothNoise(rows, cols, 12, 1.2, seed) + smoothNoise(rows, cols, 1.5, 0.05, seed + 1);
  return f;
}

// The height field's samples as a mesh, two triangles per cell split along
// the diagonal from sample (c + 1, r) to (c, r + 1), in the scene frame.
inline drivers::SimMesh heightFieldMesh(const drivers::SimHeightField& f) {
  drivers::SimMesh mesh;
  const Eigen::Vector3d n = f.normal.normalized();
  const Eigen::Vector3d x = (f.x_axis - n * n.dot(f.x_axis)).normalized();
  const Eigen::Vector3d y = n.cross(x);
  const cv::Mat& h = f.heights_mm;
  for (int r = 0; r < h.rows; ++r)
    for (int c = 0; c < h.cols; ++c) {
      const Eigen::Vector3d p = f.origin + x * (-f.width_mm / 2 + c * f.cell_mm) +
                                y * (-f.length_mm / 2 + r * f.cell_mm) +
                                n * double(h.at<float>(r, c));
      mesh.vertices.push_back(p.cast<float>());
    }
  for (int r = 0; r + 1 < h.rows; ++r)
    for (int c = 0; c + 1 < h.cols; ++c) {
      const std::int32_t i = r * h.cols + c;
      mesh.triangles.push_back({i, i + 1, i + h.cols});
      mesh.triangles.push_back({i + 1, i + h.cols + 1, i + h.cols});
    }
  mesh.albedo = f.albedo;
  return mesh;
}

// The largest height difference between the bilinear surface and
// heightFieldMesh's triangles over any cell: |h00 - h01 - h10 + h11| / 4
// (at the cell's centre).
inline double bilinearTriangleGap(const cv::Mat& heights) {
  double worst = 0;
  for (int r = 0; r + 1 < heights.rows; ++r)
    for (int c = 0; c + 1 < heights.cols; ++c) {
      const double k = double(heights.at<float>(r, c)) - heights.at<float>(r, c + 1) -
                       heights.at<float>(r + 1, c) + heights.at<float>(r + 1, c + 1);
      worst = std::max(worst, std::abs(k) / 4);
    }
  return worst;
}

}  // namespace sl::test
