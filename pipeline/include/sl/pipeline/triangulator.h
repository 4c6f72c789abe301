// Camera-projector triangulation with a precomputed determinant tensor
// (paper section 2.3, eq. 6-7). For camera pixel (u_c, v_c) with undistorted
// normalized ray r = (x, y, 1) and one projector coordinate (u_p or v_p), the
// depth is z = (c0 - p * c1) / (p * a(u_c, v_c) - b(u_c, v_c)), where a, b are
// per-pixel maps precomputed from the projection matrix M_p = K_p [R | t]; a
// point costs a few multiply-adds and one division.
#pragma once

#include <string>
#include <utility>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct TriangulatorOptions {
  // kColumns / kRows force u_p / v_p (the map must be present). kBest
  // prefers columns when the baseline is mostly horizontal (|t.x| >= |t.y|),
  // rows otherwise, and per pixel falls back to the other map where the
  // preferred one is NaN or absent (an empty cv::Mat).
  enum class Use { kColumns, kRows, kBest } use = Use::kBest;
  float min_depth_mm = 100.0f;  // points outside [min, max] depth are NaN
  float max_depth_mm = 3000.0f;
  // Iterations that correct the decoded projector coordinate for projector
  // lens distortion (0 = ignore projector distortion). The first is a plain
  // shift by the distortion at the decoded coordinate, later ones refine it.
  // With ~15 px of projector distortion, 2 iterations leave < 1e-3 mm (see
  // test_triangulator.cpp).
  int projector_distortion_iterations = 2;
  // How the iterations solve for the undistorted coordinate.
  // kEpipolar: along the camera ray's epipolar line in the projector's
  // normalized image, a line per pixel formed once (one division); each
  // iteration evaluates the Brown-Conrady polynomial on it, later ones as
  // secant steps. NaN where that line is degenerate (the coordinate does not
  // change along the ray). kAlongRay: the point is triangulated and
  // projected into the projector each iteration (a division each), later
  // ones secant steps, and a pixel whose point is behind either device keeps
  // its decoded coordinate; the reference kEpipolar is tested against (same
  // fixed point, more work per pixel: test_triangulator.cpp bounds the
  // difference, bench_codecs times both).
  enum class ProjectorCorrection { kEpipolar, kAlongRay };
  ProjectorCorrection projector_correction = ProjectorCorrection::kEpipolar;
};

// Thread-compatible (triangulate() is const and keeps no state, so concurrent
// calls on one instance are safe too). Construction precomputes the camera
// rays: a grid interpolated per row where that stays within 2e-7 (normalized
// units) of every pixel's exact ray, else 8 bytes per camera pixel.
// Arithmetic is single precision (the maps and the cloud are float);
// test_triangulator.cpp bounds the error.
class Triangulator {
 public:
  Triangulator(const CameraProjectorCalibration& calibration, TriangulatorOptions options);

  // maps.up / maps.vp / maps.offset: CV_32FC1 of the camera's size, or empty
  // (offset empty -> intensity 0). Throws std::invalid_argument otherwise or
  // when the map that options.use needs is empty. Output: organized cloud of
  // the camera's size in the camera optical frame (mm), frame_id =
  // maps.camera_id, stamp = maps.stamp_ns; x = y = z = NaN where the input is
  // NaN, the ray is parallel to the projector plane or z is outside
  // [min_depth_mm, max_depth_mm].
  PointCloud triangulate(const ProjectorMaps& maps) const;

  // Buffer-reusing, row-range form of triangulate() for callers that pipeline
  // decoding and triangulation per block of rows or split rows over their own
  // threads (the triangulator starts none). prepare() checks the maps as
  // triangulate() does and sizes `cloud` (its point buffer is reused when the
  // size is unchanged); triangulateRows() then fills rows [row_begin,
  // row_end), and concurrent calls on disjoint ranges of one cloud are safe.
  void prepare(const ProjectorMaps& maps, PointCloud& cloud) const;
  void triangulateRows(const ProjectorMaps& maps, int row_begin, int row_end,
                       PointCloud& cloud) const;

  // Fused form for callers that need only the cloud, with no camera-sized
  // maps: `band` holds camera rows [row_begin, row_end) in its rows 0 ..
  // (row_end - row_begin) (Codec::decodeBand()); its maps must be the
  // camera's width and CV_32FC1 (or empty as above). prepareCloud() sizes the
  // cloud once per scan; triangulateBand() fills the band's rows and throws
  // std::invalid_argument on a bad band or an unprepared cloud. Concurrent
  // calls on disjoint row ranges of one cloud (each with its own band) are
  // safe. Results equal triangulateRows() on full maps.
  void prepareCloud(const std::string& frame_id, TimestampNs stamp_ns, PointCloud& cloud) const;
  void triangulateBand(const ProjectorMaps& band, int row_begin, int row_end,
                       PointCloud& cloud) const;

  const TriangulatorOptions& options() const;
  // Spacing in pixels of the camera-ray grid (16, 8 or 4), or 0 when the rays
  // are stored per pixel (lenses too distorted for the grid).
  int rayGridStep() const;

 private:
  // Checks the maps (camera-sized, or a band of the camera's width with at
  // least band_rows rows when band_rows >= 0); the axes tried per pixel in
  // order (second = -1: none).
  std::pair<int, int> axesFor(const ProjectorMaps& maps, int band_rows = -1) const;
  struct Impl;
  std::shared_ptr<const Impl> impl_;
};

}  // namespace sl::pipeline
