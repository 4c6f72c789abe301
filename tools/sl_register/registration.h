// Registration of scans along one or more passes into one surface (paper
// section 4.4): point-to-plane ICP between overlapping scans, and multi-way
// refinement of all scan poses by a pose graph (neighbour edges (i, i+1),
// skip edges (i, i+k), edges between scans of different passes) optimised
// globally. ICP, normals, voxel downsampling, kd-trees and the pose-graph
// optimisation are Open3D's (Debian's libopen3d-dev); only this library's
// .cpp sees Open3D, its users see Eigen.
//
// Poses are T_world_scan (X_world = T * X_scan), millimetres, the world being
// the frame of the prior (robot poses) or, without one, of the first scan.
// Free functions, no state; thread-compatible.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace sl::reg {

using Pose = Eigen::Isometry3d;

struct ScanInput {
  std::string name;                      // for the report (e.g. the file name)
  int pass = 0;                          // scans of one pass are consecutive along the motion
  std::int64_t stamp_ns = 0;
  std::vector<Eigen::Vector3f> points;   // mm, scan frame (camera optical frame); finite
  Pose initial = Pose::Identity();       // prior pose (from robot poses or the pass's velocity)
};

struct RegisterOptions {
  double voxel_mm = 2.0;             // downsampling before normals and ICP
  double normal_radius_mm = 6.0;     // normals from neighbours within this radius (max 30)
  // ICP runs coarse to fine at these maximum correspondence distances (mm).
  std::vector<double> icp_distances_mm = {8.0, 4.0, 2.0};
  int icp_iterations = 15;           // per scale (fewer when converged)
  // An ICP scale ends early when an iteration changes the fitness by less
  // than this and the RMSE by less than this many mm (Open3D's criteria;
  // a tighter value costs time for no drift that matters: docs/registration.md,
  // docs/measurements.md).
  double icp_convergence = 1e-4;
  // An edge is tried only when at least this fraction of the source's points
  // has a target point within overlap_distance_mm under the initial guess.
  double min_overlap = 0.2;
  double overlap_distance_mm = 8.0;
  // An edge is kept only when, after ICP, at least min_fitness of the
  // source's points has a correspondence within the finest distance, their
  // point-to-plane RMSE is at most max_rmse_mm, and ICP moved the guess by at
  // most max_correction_mm / max_correction_deg (the prior's uncertainty).
  double min_fitness = 0.3;
  double max_rmse_mm = 0.5;
  double max_correction_mm = 25.0;
  double max_correction_deg = 5.0;
  // Skip edges (i, i + k) within a pass for these k (if they overlap).
  std::vector<int> skip_steps = {2, 4, 8};
  // Edges to the nearest scans of other passes (by prior centre distance),
  // at most this many per scan.
  int cross_pass_neighbours = 3;
  bool multiway = true;              // false: pairwise chain only
  // Multi-way: ICP + optimisation rounds. One: a second round (ICP again
  // from the optimised poses) changed no drift of sl_eval wall's scans by
  // 0.001 mm and doubled the time.
  int refinement_rounds = 1;
  double edge_prune_threshold = 0.25;  // Open3D's line-process threshold for loop closures
  // OpenMP threads for Open3D (process-wide; 0 = OpenMP's default). One by
  // default: Open3D's parallel loops are short and OpenMP's waiting threads
  // spin, which on a shared 2-core machine costs more than it gains.
  int threads = 1;
};

enum class EdgeKind { kNeighbour, kSkip, kCrossPass };
const char* toString(EdgeKind kind);

struct EdgeReport {
  int source = 0, target = 0;   // scan indices; the edge maps source points into target's frame
  EdgeKind kind = EdgeKind::kNeighbour;
  bool tried = false;           // false: too little overlap under the initial guess
  bool accepted = false;        // used for the poses
  std::string reason;           // why not accepted ("" when accepted)
  double overlap = 0;           // fraction, under the initial guess
  double fitness = 0;           // fraction of source points with a correspondence
  double rmse_mm = 0;           // point-to-plane RMSE of those correspondences, after ICP
  double correction_mm = 0, correction_deg = 0;  // ICP's change of the initial guess
  Eigen::Matrix4d transform = Eigen::Matrix4d::Identity();  // T_target_source measured
  // After the final poses: point-to-plane RMSE and the edge's disagreement
  // with the poses (T_target^-1 T_source against `transform`).
  double final_rmse_mm = 0;
  double final_error_mm = 0, final_error_deg = 0;
  bool pruned = false;          // multi-way: rejected by the optimisation's line process
};

struct RegisterResult {
  std::vector<Pose> poses;            // per scan (refused ones keep their initial pose)
  std::vector<bool> registered;       // false: the scan matched nothing and is left out
  std::vector<std::string> refused;   // names of the scans left out, with the reason
  std::vector<EdgeReport> edges;
  bool multiway = false;
  int reference = 0;                  // the scan whose pose was held fixed
  // Multi-way: the pairwise chain it started from, as a pairwise run
  // (RegisterOptions::multiway false) gives it, so that one run yields both;
  // null for a pairwise run.
  std::shared_ptr<const RegisterResult> pairwise;
};

// Called with a line of progress ("ICP 12/80 scan_0003 -> scan_0004 ...").
using Progress = std::function<void(const std::string&)>;

// Registers the scans. Throws std::invalid_argument on no scans or a scan
// without enough points. A scan that no accepted edge connects to the
// reference scan is not registered and named in `refused`.
RegisterResult registerScans(const std::vector<ScanInput>& scans, const RegisterOptions& options,
                             const Progress& progress = {});

// The report as text: per-edge lines (kind, fitness, RMSE, correction,
// final residuals), the refused scans and summary statistics.
std::string formatReport(const std::vector<ScanInput>& scans, const RegisterResult& result);

}  // namespace sl::reg
