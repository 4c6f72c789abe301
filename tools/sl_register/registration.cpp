// The only translation unit that includes Open3D (its headers are heavy).
#include "registration.h"

#include <open3d/geometry/KDTreeFlann.h>
#include <open3d/geometry/KDTreeSearchParam.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/GlobalOptimization.h>
#include <open3d/pipelines/registration/GlobalOptimizationConvergenceCriteria.h>
#include <open3d/pipelines/registration/GlobalOptimizationMethod.h>
#include <open3d/pipelines/registration/PoseGraph.h>
#include <open3d/pipelines/registration/Registration.h>
#include <open3d/pipelines/registration/TransformationEstimation.h>
#include <open3d/utility/Logging.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <numeric>
#include <set>
#include <sstream>
#include <stdexcept>

namespace sl::reg {

namespace {

namespace o3g = open3d::geometry;
namespace o3r = open3d::pipelines::registration;

constexpr double kPi = 3.14159265358979323846;
constexpr std::size_t kMinPoints = 50;  // after downsampling

struct Prepared {
  std::shared_ptr<o3g::PointCloud> cloud;  // downsampled, with normals (scan frame)
  std::shared_ptr<o3g::KDTreeFlann> tree;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
};

Prepared prepare(const ScanInput& scan, const RegisterOptions& options) {
  o3g::PointCloud full;
  full.points_.reserve(scan.points.size());
  for (const Eigen::Vector3f& p : scan.points)
    if (p.allFinite()) full.points_.push_back(p.cast<double>());
  Prepared prepared;
  prepared.cloud = full.VoxelDownSample(options.voxel_mm);
  if (prepared.cloud->points_.size() < kMinPoints)
    throw std::invalid_argument("scan '" + scan.name + "': " +
                                std::to_string(prepared.cloud->points_.size()) + " points after " +
                                std::to_string(options.voxel_mm) +
                                " mm voxels, registration needs at least " +
                                std::to_string(kMinPoints));
  prepared.cloud->EstimateNormals(o3g::KDTreeSearchParamHybrid(options.normal_radius_mm, 30));
  prepared.cloud->OrientNormalsTowardsCameraLocation(Eigen::Vector3d::Zero());
  prepared.tree = std::make_shared<o3g::KDTreeFlann>(*prepared.cloud);
  for (const Eigen::Vector3d& p : prepared.cloud->points_) prepared.centroid += p;
  prepared.centroid /= double(prepared.cloud->points_.size());
  return prepared;
}

struct Fit {
  double fitness = 0;  // fraction of source points with a target point within the distance
  double rmse_mm = 0;  // point-to-plane, over those
};

// Correspondences of source points moved by T (into target's frame) with
// their nearest target point within max_distance.
Fit evaluate(const Prepared& source, const Prepared& target, const Eigen::Matrix4d& T,
             double max_distance) {
  const auto& points = source.cloud->points_;
  const auto& target_points = target.cloud->points_;
  const auto& normals = target.cloud->normals_;
  std::vector<int> index(1);
  std::vector<double> d2(1);
  double sum = 0;
  std::size_t count = 0;
  const Eigen::Matrix3d R = T.block<3, 3>(0, 0);
  const Eigen::Vector3d t = T.block<3, 1>(0, 3);
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector3d q = R * p + t;
    if (target.tree->SearchKNN(q, 1, index, d2) < 1 || d2[0] > max_distance * max_distance)
      continue;
    const double r = normals[std::size_t(index[0])].dot(q - target_points[std::size_t(index[0])]);
    sum += r * r;
    ++count;
  }
  Fit fit;
  fit.fitness = points.empty() ? 0 : double(count) / double(points.size());
  fit.rmse_mm = count ? std::sqrt(sum / double(count)) : 0;
  return fit;
}

double angleDeg(const Eigen::Matrix3d& R) {
  return Eigen::AngleAxisd(R).angle() * 180.0 / kPi;
}

// Difference between two rigid transforms: translation (mm) and rotation (deg).
std::pair<double, double> difference(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) {
  const Eigen::Matrix4d d = a * b.inverse();
  return {d.block<3, 1>(0, 3).norm(), angleDeg(d.block<3, 3>(0, 0))};
}

// Seconds since the last lap (or construction), as text for progress lines.
class Stopwatch {
 public:
  std::string lap() {
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.1f", s);
    return buffer;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

// Measured edge with what the optimisation needs.
struct Measured {
  EdgeReport report;
  Eigen::Matrix6d information = Eigen::Matrix6d::Identity();
};

class Registrar {
 public:
  Registrar(const std::vector<ScanInput>& scans, const RegisterOptions& options,
            const Progress& progress)
      : scans_(scans), options_(options), progress_(progress) {
    if (scans.empty()) throw std::invalid_argument("registration: no scans");
    if (options.icp_distances_mm.empty())
      throw std::invalid_argument("registration: no ICP distances");
    finest_ = *std::min_element(options.icp_distances_mm.begin(), options.icp_distances_mm.end());
    for (std::size_t i = 0; i < scans.size(); ++i) {
      say("prepare " + std::to_string(i + 1) + "/" + std::to_string(scans.size()) + " " +
          scans[i].name + " (" + std::to_string(scans[i].points.size()) + " points)");
      prepared_.push_back(prepare(scans[i], options));
    }
  }

  RegisterResult run() {
    poses_.clear();
    for (const ScanInput& s : scans_) poses_.push_back(s.initial);
    registered_.assign(scans_.size(), false);
    registered_[0] = true;
    Stopwatch watch;
    chain();
    say("pairwise chain: " + std::to_string(icp_count_) + " edges measured in " + watch.lap() + " s");
    if (!options_.multiway) return finish(chain_edges_, false);
    const auto pairwise = std::make_shared<const RegisterResult>(finish(chain_edges_, false));
    std::vector<Measured> final_edges;
    for (int round = 0; round < std::max(1, options_.refinement_rounds); ++round) {
      say("multi-way round " + std::to_string(round + 1));
      const int before = icp_count_;
      std::vector<Measured> edges = measureAll(round == 0);
      say("multi-way round " + std::to_string(round + 1) + ": " + std::to_string(edges.size()) +
          " edges (" + std::to_string(icp_count_ - before) + " measured) in " + watch.lap() + " s");
      optimise(edges);
      say("multi-way round " + std::to_string(round + 1) + ": pose graph in " + watch.lap() + " s");
      final_edges = std::move(edges);
    }
    RegisterResult result = finish(std::move(final_edges), true);
    result.pairwise = pairwise;
    return result;
  }

 private:
  void say(const std::string& line) const {
    if (progress_) progress_(line);
  }

  // The result under the current poses with `edges` (the current poses are
  // left as they are): scans connected to the reference through kept edges
  // are registered, the others keep their initial pose and are refused; the
  // kept edges' final residuals.
  RegisterResult finish(std::vector<Measured> edges, bool multiway) {
    const std::vector<Pose> current = poses_;
    RegisterResult result;
    result.multiway = multiway;
    result.reference = 0;
    const std::vector<bool> reached = connected(edges);
    for (std::size_t i = 0; i < scans_.size(); ++i) {
      if (reached[i]) continue;
      poses_[i] = scans_[i].initial;
      result.refused.push_back(scans_[i].name + ": matches no other scan (no edge kept)");
    }
    for (Measured& m : edges) {
      EdgeReport& e = m.report;
      if (!e.accepted) continue;
      const Eigen::Matrix4d T = relative(e.source, e.target);
      e.final_rmse_mm = evaluate(prepared_[std::size_t(e.source)], prepared_[std::size_t(e.target)],
                                 T, finest_)
                            .rmse_mm;
      std::tie(e.final_error_mm, e.final_error_deg) = difference(T, e.transform);
    }
    for (const Measured& m : edges) result.edges.push_back(m.report);
    result.poses = poses_;
    result.registered = reached;
    poses_ = current;
    return result;
  }

  // T_target_source from the current poses.
  Eigen::Matrix4d relative(int source, int target) const {
    return (poses_[std::size_t(target)].inverse() * poses_[std::size_t(source)]).matrix();
  }

  EdgeKind kindOf(int source, int target) const {
    const ScanInput& a = scans_[std::size_t(source)];
    const ScanInput& b = scans_[std::size_t(target)];
    if (a.pass != b.pass) return EdgeKind::kCrossPass;
    return std::abs(target - source) == 1 ? EdgeKind::kNeighbour : EdgeKind::kSkip;
  }

  // ICP of `source` into `target` from the guess T_target_source.
  // fine: the guess is already close (poses from the chain or an earlier
  // round): ICP skips the coarsest distance.
  Measured measure(int source, int target, const Eigen::Matrix4d& guess, bool fine = false) {
    Measured m;
    EdgeReport& e = m.report;
    e.source = source;
    e.target = target;
    e.kind = kindOf(source, target);
    const Prepared& s = prepared_[std::size_t(source)];
    const Prepared& t = prepared_[std::size_t(target)];
    ++icp_count_;
    const std::string label = scans_[std::size_t(source)].name + " -> " +
                              scans_[std::size_t(target)].name + " (" + toString(e.kind) + ")";
    e.overlap = evaluate(s, t, guess, options_.overlap_distance_mm).fitness;
    if (e.overlap < options_.min_overlap) {
      char buffer[96];
      std::snprintf(buffer, sizeof buffer, "too little overlap (%.2f < %.2f)", e.overlap,
                    options_.min_overlap);
      e.reason = buffer;
      return m;
    }
    e.tried = true;
    Eigen::Matrix4d T = guess;
    std::vector<double> distances = options_.icp_distances_mm;
    std::sort(distances.begin(), distances.end(), std::greater<>());
    if (fine && distances.size() > 1) distances.erase(distances.begin());
    for (double d : distances) {
      const o3r::RegistrationResult r = o3r::RegistrationICP(
          *s.cloud, *t.cloud, d, T, o3r::TransformationEstimationPointToPlane(),
          o3r::ICPConvergenceCriteria(options_.icp_convergence, options_.icp_convergence,
                                      options_.icp_iterations));
      T = r.transformation_;
    }
    e.transform = T;
    const Fit fit = evaluate(s, t, T, finest_);
    e.fitness = fit.fitness;
    e.rmse_mm = fit.rmse_mm;
    std::tie(e.correction_mm, e.correction_deg) = difference(T, guess);
    char buffer[160];
    if (e.fitness < options_.min_fitness) {
      std::snprintf(buffer, sizeof buffer, "poor fit: fitness %.2f < %.2f", e.fitness,
                    options_.min_fitness);
      e.reason = buffer;
    } else if (e.rmse_mm > options_.max_rmse_mm) {
      std::snprintf(buffer, sizeof buffer, "poor fit: RMSE %.3f mm > %.3f mm", e.rmse_mm,
                    options_.max_rmse_mm);
      e.reason = buffer;
    } else if (e.correction_mm > options_.max_correction_mm ||
               e.correction_deg > options_.max_correction_deg) {
      std::snprintf(buffer, sizeof buffer,
                    "ICP moved the guess by %.1f mm / %.2f deg (limit %.1f mm / %.2f deg)",
                    e.correction_mm, e.correction_deg, options_.max_correction_mm,
                    options_.max_correction_deg);
      e.reason = buffer;
    } else {
      e.accepted = true;
      m.information = o3r::GetInformationMatrixFromPointClouds(*s.cloud, *t.cloud, finest_, T);
    }
    std::snprintf(buffer, sizeof buffer, ": overlap %.2f fitness %.3f rmse %.3f mm %s",
                  e.overlap, e.fitness, e.rmse_mm, e.accepted ? "kept" : e.reason.c_str());
    say("ICP " + std::to_string(icp_count_) + " " + label + buffer);
    return m;
  }

  // Scans of other passes nearest to scan j (by centroid under the current
  // poses), among those for which `eligible` holds.
  template <typename Eligible>
  std::vector<int> crossCandidates(int j, Eligible eligible) const {
    std::vector<std::pair<double, int>> near;
    const Eigen::Vector3d cj = poses_[std::size_t(j)] * prepared_[std::size_t(j)].centroid;
    for (std::size_t i = 0; i < scans_.size(); ++i) {
      if (scans_[i].pass == scans_[std::size_t(j)].pass || !eligible(int(i))) continue;
      near.push_back({(poses_[i] * prepared_[i].centroid - cj).norm(), int(i)});
    }
    std::sort(near.begin(), near.end());
    std::vector<int> out;
    for (std::size_t k = 0; k < near.size() && int(k) < options_.cross_pass_neighbours; ++k)
      out.push_back(near[k].second);
    return out;
  }

  // Pairwise: each scan's pose from the first accepted edge to an earlier
  // registered scan (its predecessors in the pass first, then other passes),
  // the guess being that scan's pose moved by the prior's relative motion;
  // then scans still unplaced from their registered successors in the pass.
  void chain() {
    chain_edges_.clear();
    for (int j = 1; j < int(scans_.size()); ++j) {
      std::vector<int> candidates;
      for (int i = j - 1; i >= std::max(0, j - 3); --i)
        if (scans_[std::size_t(i)].pass == scans_[std::size_t(j)].pass && registered_[std::size_t(i)])
          candidates.push_back(i);
      for (int i : crossCandidates(j, [&](int i) { return i < j && registered_[std::size_t(i)]; }))
        candidates.push_back(i);
      for (int i : candidates) {
        // Prior guess of P_j from P_i and the prior's relative motion.
        const Pose guess_j =
            poses_[std::size_t(i)] * scans_[std::size_t(i)].initial.inverse() * scans_[std::size_t(j)].initial;
        const Eigen::Matrix4d guess = (guess_j.inverse() * poses_[std::size_t(i)]).matrix();
        Measured m = measure(i, j, guess);
        const bool ok = m.report.accepted;
        if (ok) poses_[std::size_t(j)] = poses_[std::size_t(i)] * Pose(m.report.transform).inverse();
        chain_edges_.push_back(std::move(m));
        if (ok) {
          registered_[std::size_t(j)] = true;
          break;
        }
      }
      if (!registered_[std::size_t(j)]) {
        // Keep the pass moving on the prior from the last registered scan.
        for (int i = j - 1; i >= 0; --i)
          if (registered_[std::size_t(i)]) {
            poses_[std::size_t(j)] = poses_[std::size_t(i)] * scans_[std::size_t(i)].initial.inverse() *
                                     scans_[std::size_t(j)].initial;
            break;
          }
        say("scan " + scans_[std::size_t(j)].name + ": no match to an earlier scan");
      }
    }
    // Backwards: a scan left out (e.g. the first scans of a pass that
    // overlap no earlier pass enough) is placed from its successors in the
    // pass, once one of them is registered.
    for (int j = int(scans_.size()) - 2; j >= 0; --j) {
      if (registered_[std::size_t(j)]) continue;
      for (int i = j + 1; i <= std::min(int(scans_.size()) - 1, j + 3); ++i) {
        if (scans_[std::size_t(i)].pass != scans_[std::size_t(j)].pass || !registered_[std::size_t(i)])
          continue;
        const Pose guess_j =
            poses_[std::size_t(i)] * scans_[std::size_t(i)].initial.inverse() * scans_[std::size_t(j)].initial;
        const Eigen::Matrix4d guess = (guess_j.inverse() * poses_[std::size_t(i)]).matrix();
        Measured m = measure(i, j, guess);
        const bool ok = m.report.accepted;
        if (ok) poses_[std::size_t(j)] = poses_[std::size_t(i)] * Pose(m.report.transform).inverse();
        chain_edges_.push_back(std::move(m));
        if (ok) {
          registered_[std::size_t(j)] = true;
          say("scan " + scans_[std::size_t(j)].name + ": placed from a later scan of its pass");
          break;
        }
      }
      if (!registered_[std::size_t(j)]) say("scan " + scans_[std::size_t(j)].name + ": no pairwise match");
    }
  }

  // Every candidate edge (neighbours, skips, nearest scans of other passes),
  // measured from the current poses; then the scans connected to the
  // reference through accepted edges are the registered ones.
  std::vector<Measured> measureAll(bool reuse_chain) {
    std::set<std::pair<int, int>> pairs;
    const int n = int(scans_.size());
    std::vector<int> steps = options_.skip_steps;
    steps.push_back(1);
    for (int i = 0; i < n; ++i) {
      for (int k : steps) {
        const int j = i + k;
        if (k >= 1 && j < n && scans_[std::size_t(j)].pass == scans_[std::size_t(i)].pass)
          pairs.insert({i, j});
      }
      for (int j : crossCandidates(i, [](int) { return true; }))
        pairs.insert({std::min(i, j), std::max(i, j)});
    }
    std::vector<Measured> edges;
    for (const auto& [i, j] : pairs) {
      // The chain's edge that placed j is already measured from this very guess.
      const auto same = std::find_if(chain_edges_.begin(), chain_edges_.end(), [&](const Measured& m) {
        return m.report.source == i && m.report.target == j && m.report.accepted;
      });
      if (reuse_chain && same != chain_edges_.end() &&
          difference(same->report.transform, relative(i, j)).first < 1e-9) {
        edges.push_back(*same);
        continue;
      }
      edges.push_back(measure(i, j, relative(i, j), registered_[std::size_t(i)] &&
                                                        registered_[std::size_t(j)]));
    }
    registered_ = connected(edges);
    return edges;
  }

  // Scans reached from the reference (0) through accepted, unpruned edges.
  std::vector<bool> connected(const std::vector<Measured>& edges) const {
    std::vector<std::vector<int>> adjacent(scans_.size());
    for (const Measured& m : edges)
      if (m.report.accepted && !m.report.pruned) {
        adjacent[std::size_t(m.report.source)].push_back(m.report.target);
        adjacent[std::size_t(m.report.target)].push_back(m.report.source);
      }
    std::vector<bool> reached(scans_.size(), false);
    std::vector<int> stack{0};
    reached[0] = true;
    while (!stack.empty()) {
      const int n = stack.back();
      stack.pop_back();
      for (int m : adjacent[std::size_t(n)])
        if (!reached[std::size_t(m)]) reached[std::size_t(m)] = true, stack.push_back(m);
    }
    return reached;
  }

  // Open3D's global optimisation (Levenberg-Marquardt with a line process on
  // the uncertain edges) over the registered scans; the reference keeps its pose.
  void optimise(std::vector<Measured>& edges) {
    std::vector<int> node_of(scans_.size(), -1), scan_of;
    o3r::PoseGraph graph;
    for (std::size_t i = 0; i < scans_.size(); ++i) {
      if (!registered_[i]) continue;
      node_of[i] = int(scan_of.size());
      scan_of.push_back(int(i));
      graph.nodes_.emplace_back(poses_[i].matrix());
    }
    std::vector<std::size_t> edge_of;
    for (std::size_t k = 0; k < edges.size(); ++k) {
      const EdgeReport& e = edges[k].report;
      if (!e.accepted || !registered_[std::size_t(e.source)] || !registered_[std::size_t(e.target)])
        continue;
      graph.edges_.emplace_back(node_of[std::size_t(e.source)], node_of[std::size_t(e.target)],
                                e.transform, edges[k].information,
                                e.kind != EdgeKind::kNeighbour);
      edge_of.push_back(k);
    }
    const std::size_t before = graph.edges_.size();
    o3r::GlobalOptimization(graph, o3r::GlobalOptimizationLevenbergMarquardt(),
                            o3r::GlobalOptimizationConvergenceCriteria(),
                            o3r::GlobalOptimizationOption(finest_, options_.edge_prune_threshold,
                                                          1.0, 0));
    // Edges the line process pruned are missing from the returned graph.
    std::set<std::pair<int, int>> kept;
    for (const o3r::PoseGraphEdge& e : graph.edges_)
      kept.insert({scan_of[std::size_t(e.source_node_id_)], scan_of[std::size_t(e.target_node_id_)]});
    for (std::size_t k : edge_of) {
      EdgeReport& e = edges[k].report;
      if (!kept.count({e.source, e.target})) {
        e.pruned = true;
        e.reason = "pruned by the pose-graph optimisation (inconsistent with the other edges)";
      }
    }
    say("pose graph: " + std::to_string(graph.nodes_.size()) + " scans, " +
        std::to_string(before) + " edges, " + std::to_string(before - graph.edges_.size()) +
        " pruned");
    const Eigen::Matrix4d fix = poses_[0].matrix() * graph.nodes_[0].pose_.inverse();
    for (std::size_t n = 0; n < scan_of.size(); ++n)
      poses_[std::size_t(scan_of[n])] = Pose(fix * graph.nodes_[n].pose_);
  }

  const std::vector<ScanInput>& scans_;
  const RegisterOptions& options_;
  const Progress& progress_;
  std::vector<Prepared> prepared_;
  std::vector<Pose> poses_;
  std::vector<bool> registered_;
  std::vector<Measured> chain_edges_;
  double finest_ = 0;
  int icp_count_ = 0;
};

}  // namespace

const char* toString(EdgeKind kind) {
  switch (kind) {
    case EdgeKind::kNeighbour: return "neighbour";
    case EdgeKind::kSkip: return "skip";
    case EdgeKind::kCrossPass: return "cross-pass";
  }
  return "?";
}

RegisterResult registerScans(const std::vector<ScanInput>& scans, const RegisterOptions& options,
                             const Progress& progress) {
  open3d::utility::SetVerbosityLevel(open3d::utility::VerbosityLevel::Error);
  if (options.threads > 0) omp_set_num_threads(options.threads);
  Registrar registrar(scans, options, progress);
  return registrar.run();
}

std::string formatReport(const std::vector<ScanInput>& scans, const RegisterResult& result) {
  std::ostringstream out;
  char line[512];
  out << "# sl_register report (" << (result.multiway ? "multi-way" : "pairwise") << ", "
      << scans.size() << " scans, reference " << scans[std::size_t(result.reference)].name << ")\n";
  out << "# source target kind status overlap fitness rmse_mm correction_mm correction_deg "
         "final_rmse_mm final_error_mm final_error_deg reason\n";
  std::vector<double> rmse, error_mm, error_deg;
  int kept = 0, rejected = 0, untried = 0, pruned = 0;
  for (const EdgeReport& e : result.edges) {
    const char* status = !e.tried ? "untried" : e.pruned ? "pruned" : e.accepted ? "kept" : "rejected";
    std::snprintf(line, sizeof line, "edge %s %s %s %s %.3f %.3f %.4f %.3f %.3f %.4f %.4f %.4f %s\n",
                  scans[std::size_t(e.source)].name.c_str(), scans[std::size_t(e.target)].name.c_str(),
                  toString(e.kind), status, e.overlap, e.fitness, e.rmse_mm, e.correction_mm,
                  e.correction_deg, e.final_rmse_mm, e.final_error_mm, e.final_error_deg,
                  e.reason.empty() ? "-" : e.reason.c_str());
    out << line;
    if (!e.tried) ++untried;
    else if (e.pruned) ++pruned;
    else if (e.accepted) {
      ++kept;
      rmse.push_back(e.final_rmse_mm);
      error_mm.push_back(e.final_error_mm);
      error_deg.push_back(e.final_error_deg);
    } else ++rejected;
  }
  for (const std::string& r : result.refused) out << "refused " << r << "\n";
  auto mean = [](const std::vector<double>& v) {
    return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
  };
  auto max = [](const std::vector<double>& v) {
    return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
  };
  std::snprintf(line, sizeof line,
                "summary: %d edges kept, %d rejected, %d with too little overlap, %d pruned; "
                "%zu of %zu scans refused; final point-to-plane RMSE mean %.4f max %.4f mm; "
                "edge disagreement mean %.4f max %.4f mm, mean %.4f max %.4f deg\n",
                kept, rejected, untried, pruned, result.refused.size(), scans.size(), mean(rmse),
                max(rmse), mean(error_mm), max(error_mm), mean(error_deg), max(error_deg));
  out << line;
  return out.str();
}

}  // namespace sl::reg
