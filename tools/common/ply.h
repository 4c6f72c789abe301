// Point cloud files: binary PLY (finite points) and binary PCD (organized,
// NaN kept), both written atomically (temporary file + rename).
#pragma once

#include <cstddef>
#include <string>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/types.h"

namespace sl::tools {

enum class LengthUnit { kMillimetre, kMetre };

// Writes the finite points of `cloud` as binary little-endian PLY with float
// x, y, z (in `unit`) and intensity, and the organized size, unit and frame as
// header comments. Returns the number of points written; throws
// std::runtime_error naming the file on I/O failure.
std::size_t writePly(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit);

// Writes `cloud` as binary PCD v0.7 (the Point Cloud Library's format),
// organized: WIDTH x HEIGHT as the camera, fields x y z intensity (float),
// invalid points as NaN, x y z in `unit`. Returns the number of finite points.
// writePly with per-point quality (pipeline/point_quality.h) as further
// float properties, each optional (empty Mat: left out): `confidence` from
// depth_sigma (CV_32FC1, the cloud's unit, converted to `unit`) and nx ny nz
// from normals (CV_32FC3, unit vectors; the names Open3D and PCL's PLY reader
// take as normals). Both must have the cloud's organized size; a point whose
// sigma or normal is NaN keeps NaN there. Throws std::invalid_argument on a
// size or type mismatch, std::runtime_error on I/O failure.
std::size_t writePlyWithQuality(const pipeline::PointCloud& cloud, const cv::Mat& depth_sigma,
                                const cv::Mat& normals, const std::string& path, LengthUnit unit);

std::size_t writePcd(const pipeline::PointCloud& cloud, const std::string& path, LengthUnit unit);

}  // namespace sl::tools
