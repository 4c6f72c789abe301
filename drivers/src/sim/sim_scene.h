// Per-pixel geometry of the simulated camera view, computed once per scene:
// which surface each camera pixel sees, whether the projector lights it, where
// in the projector image the light comes from and how bright it arrives.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <vector>

#include "sl/drivers/sim.h"

namespace sl::drivers::sim {

// Nearest intersection of a ray with the scene.
struct SurfaceHit {
  double distance;         // ray parameter s of origin + s * direction (> 0)
  Eigen::Vector3d normal;  // unit, outward for spheres, as configured for planes
  double albedo;
  const SimPlane* plane = nullptr;  // the plane hit (in the scene), nullptr for spheres
};

// Nearest intersection of origin + s * direction with s in (min_s, max_s), or
// nullopt. direction need not be unit; distances are in units of |direction|.
std::optional<SurfaceHit> intersectScene(const SimScene& scene, const Eigen::Vector3d& origin,
                                         const Eigen::Vector3d& direction, double min_s,
                                         double max_s);

// What the renderer needs per camera pixel (row-major, camera size), stored
// as separate arrays so the render loop streams through them.
struct RenderMaps {
  int width = 0;          // camera px
  int height = 0;         // camera px
  int texture_width = 0;  // projector px: row stride of the pattern images
  // Ambient signal in 8-bit DN: ambient_dn * albedo, 0 where no surface.
  std::vector<float> ambient_dn;
  // Projector signal per unit of 8-bit pattern value, in 8-bit DN:
  // projector_brightness_dn * shading / 255, 0 where not lit.
  std::vector<float> projector_dn_per_level;
  // Bilinear sampling of the pattern image at (up, vp): index of the top-left
  // texel (y0 * texture_width + x0) and the weights of x0 + 1 and y0 + 1.
  // Unlit pixels sample texel 0 with zero weights (their factor above is 0).
  std::vector<std::int32_t> texel_index;
  std::vector<float> weight_x;
  std::vector<float> weight_y;
};

struct SceneView {
  SimGroundTruth ground_truth;
  RenderMaps maps;
};

// Ray-casts every camera pixel of the rig against the scene. config must be
// valid (see validateConfig).
SceneView computeSceneView(const SimConfig& config);

}  // namespace sl::drivers::sim
