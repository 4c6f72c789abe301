// Triangle meshes for the simulator's ray casting: a bounding volume
// hierarchy over the triangles, in the scene frame.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "sl/drivers/sim.h"

namespace sl::drivers::sim {

// A mesh placed in the scene (vertices transformed by its pose once) with a
// binary BVH of axis-aligned boxes: leaves of at most 4 triangles, split at
// the median centroid along the widest axis. Immutable after construction,
// so thread-safe.
class MeshBvh {
 public:
  explicit MeshBvh(const SimMesh& mesh);

  // Nearest triangle hit by origin + s * direction with s in (min_s, max_s):
  // true, s and the triangle's unit normal (orientation as wound:
  // (b - a) x (c - a)); false if none.
  bool intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double min_s,
                 double max_s, double& s, Eigen::Vector3d& normal) const;

  const SimMesh& mesh() const { return *mesh_; }
  std::size_t nodeCount() const { return nodes_.size(); }

 private:
  struct Node {
    Eigen::Vector3f lo, hi;  // box, scene frame (mm)
    std::int32_t first = 0;  // leaf: first triangle; inner: left child (right = first + 1)
    std::int32_t count = 0;  // leaf: triangle count (> 0); inner: 0
  };
  // Triangles in BVH order: a vertex and two edges (scene frame, mm).
  struct Triangle {
    Eigen::Vector3d a, ab, ac;
  };

  // Fills node `node` for triangles order[first, first + count).
  void build(std::size_t node, std::vector<std::int32_t>& order, std::int32_t first,
             std::int32_t count, const std::vector<Eigen::Vector3d>& centroids,
             const std::vector<Triangle>& triangles);

  const SimMesh* mesh_;
  std::vector<Triangle> triangles_;
  std::vector<Node> nodes_;
};

}  // namespace sl::drivers::sim
