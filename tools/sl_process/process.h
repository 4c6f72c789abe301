// Offline processing of recorded captures (the core of sl_process, also used
// by the tests): read a folder of frames, decode with a pattern's codec,
// triangulate with a calibration, write maps, cloud and previews.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/triangulator.h"

namespace sl::tools {

// Image files of `dir` (png, bmp, tif, tiff, pgm; case-insensitive), sorted
// by name. Throws std::runtime_error when the folder cannot be read.
std::vector<std::string> listImages(const std::string& dir);

struct LoadedFrames {
  std::vector<cv::Mat> frames;  // CV_8UC1 or CV_16UC1, all one size
  int bit_depth = 8;            // 8 or 16 (the container depth)
};
// Reads the images as single-channel 8- or 16-bit (colour is converted to
// grey). Throws std::runtime_error naming the file on a read error or on
// mixed sizes or depths.
LoadedFrames loadFrames(const std::vector<std::string>& paths);

struct ProcessResult {
  pipeline::ProjectorMaps maps;
  pipeline::PointCloud cloud;  // mm, camera optical frame
};

// Decodes and triangulates one capture. The camera size of the calibration
// must equal the frames' size (std::invalid_argument otherwise).
//
// With undistort_images the frames are first resampled (bilinear) onto the
// ideal pinhole camera of the same K, and triangulated with a distortion-free
// camera: maps and cloud are then indexed by undistorted pixels, SLStudio's
// convention (its reference reconstructions are in that grid). Otherwise
// pixels stay in the distorted (raw) image and the triangulator undistorts
// each ray.
ProcessResult processCapture(const pipeline::PatternSpec& pattern,
                             const pipeline::CameraProjectorCalibration& calibration,
                             const LoadedFrames& frames, const pipeline::DecoderOptions& decoder,
                             const pipeline::TriangulatorOptions& triangulator,
                             bool undistort_images = false);

// Writes into `out_dir` (created if missing):
//   up.tiff, vp.tiff, modulation.tiff, offset.tiff, depth.tiff: 32-bit float
//     TIFF (projector px / camera DN / mm), NaN where invalid
//   status.png: 8-bit PixelStatus per pixel (0 valid, 1 low modulation,
//     2 saturated, 3 unwrap inconsistent, 4 out of range)
//   cloud.ply: binary PLY of the valid points (mm)
//   depth.png, modulation.png: 8-bit previews (depth: near bright, invalid
//     black, stretched over the 1st..99th percentile; modulation: 0..255 DN
//     at 8 bits, clipped)
// Returns the number of points written. Throws std::runtime_error on I/O errors.
std::size_t writeOutputs(const ProcessResult& result, int bit_depth, const std::string& out_dir);

}  // namespace sl::tools
