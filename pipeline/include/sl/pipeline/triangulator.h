// Camera-projector triangulation with a precomputed determinant tensor
// (paper section 2.3, eq. 6-7). For camera pixel (u_c, v_c) with undistorted
// normalized ray r = (x, y, 1) and one projector coordinate (u_p or v_p), the
// depth is z = (c0 - p * c1) / (p * a(u_c, v_c) - b(u_c, v_c)), where a, b are
// per-pixel maps precomputed from the projection matrix M_p = K_p [R | t]; a
// point costs a few multiply-adds and one division.
#pragma once

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct TriangulatorOptions {
  // Use u_p (projector columns) when available, else v_p. With both maps
  // present, kColumns / kRows force one; kBest picks the better conditioned.
  enum class Use { kColumns, kRows, kBest } use = Use::kBest;
  float min_depth_mm = 100.0f;  // points outside [min, max] depth are NaN
  float max_depth_mm = 3000.0f;
  // Iterations that correct the decoded projector coordinate for projector
  // lens distortion (0 = ignore projector distortion).
  int projector_distortion_iterations = 2;
};

// Thread-compatible. Construction precomputes O(width*height) maps.
class Triangulator {
 public:
  Triangulator(const CameraProjectorCalibration& calibration, TriangulatorOptions options);

  // maps must have the camera's size; intensity is taken from maps.offset.
  PointCloud triangulate(const ProjectorMaps& maps) const;

 private:
  struct Impl;
  std::shared_ptr<const Impl> impl_;
};

}  // namespace sl::pipeline
