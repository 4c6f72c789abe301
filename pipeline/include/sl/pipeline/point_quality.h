// Per-point quality of an organized cloud: the expected depth standard
// deviation of each point from the camera noise and the triangulation
// geometry, and surface normals from the organized neighbourhood.
//
// Depth sigma (docs/metrology.md, docs/simulator.md "Simulated camera noise
// model"): a pixel with offset A and modulation B (8-bit DN) of an N-step
// phase shift has the phase noise sigma_phi = sqrt(2 / N) sigma_I / B with
// sigma_I^2 = gain A + read^2 + q^2 / 12 (q one 8-bit step of the camera's
// bit depth), i.e. sigma_u = sigma_phi P / (2 pi) projector px (P the finest
// period of the axis that triangulated the point), and the depth sigma
// sigma_z = sigma_u / |du_p / dz| with du_p / dz the projector coordinate's
// rate of change along the pixel's camera ray (projector lens distortion
// included). 2+1 patterns have sqrt(2) in place of sqrt(2 / N).
//
// Pure functions, no state, no threads: thread-safe.
#pragma once

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/pattern_spec.h"
#include "sl/pipeline/triangulator.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// The camera's intensity noise on the 8-bit scale (the simulator's
// sim.radiometry keys; for a real camera from its EMVA 1288 sheet or a
// measurement, docs/metrology.md): variance gain * signal + read^2, then the
// quantisation of bit_depth bits.
struct CameraNoise {
  double gain_dn_per_electron = 0.0084;  // shot noise: var = gain * A (8-bit DN^2)
  double read_noise_dn = 0.05;           // std, 8-bit DN
  int bit_depth = 8;                     // of the images the maps were decoded from
};

// Projector coordinate sigma (projector px) per pixel along the given axis
// (columns: u_p, else v_p), CV_32FC1 of the maps' size, NaN where B <= 0 or
// is NaN. maps.offset and maps.modulation must be present (camera DN of
// noise.bit_depth). Throws std::invalid_argument for a pattern family
// without a phase (Gray code, micro phase shift) or missing maps.
cv::Mat projectorCoordinateSigma(const ProjectorMaps& maps, const PatternSpec& spec,
                                 const CameraNoise& noise, bool columns);

// Expected depth (z) sigma of every point of `cloud` (triangulated from
// `maps` with `calibration` and `use`, in the calibration's length unit),
// CV_32FC1 of the cloud's size in the same unit, NaN where the point is NaN.
// The axis per pixel follows the Triangulator's choice for `use` (kBest:
// columns when |t.x| >= |t.y| and u_p is valid, else v_p).
cv::Mat depthSigma(const ProjectorMaps& maps, const PointCloud& cloud,
                   const CameraProjectorCalibration& calibration, const PatternSpec& spec,
                   const CameraNoise& noise, TriangulatorOptions::Use use);

// Unit normals (CV_32FC3, x y z) of an organized cloud from the cross product
// of the central differences `step` pixels apart along the row and the
// column (PCL's AVERAGE_3D_GRADIENT idea, without its smoothing), oriented
// towards the camera (n . p < 0). NaN where a neighbour is NaN, lies beyond
// the image or farther than `max_jump` (the cloud's unit) from the point (a
// depth discontinuity). Throws std::invalid_argument when step < 1.
cv::Mat organizedNormals(const PointCloud& cloud, int step, float max_jump);

}  // namespace sl::pipeline
