// Per-pixel geometry of the simulated camera view, computed once per sensor
// pose: which surface each camera pixel sees, whether the projector lights it,
// where in the projector image the light comes from and how bright it arrives.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <vector>

#include "sim_mesh.h"
#include "sl/drivers/sim.h"

namespace sl::drivers::sim {

// Nearest intersection of a ray with the scene.
struct SurfaceHit {
  double distance;         // ray parameter s of origin + s * direction (> 0)
  Eigen::Vector3d normal;  // unit; outward for solids, as configured for planes
  double albedo;
  const SimPlane* plane = nullptr;  // the plane hit (in the scene), nullptr otherwise
  const void* primitive = nullptr;  // the primitive hit (any kind), for coherence tests
  bool textured = false;            // albedo varies over the surface (from a texture)
};

// A scene prepared for ray casting (unit normals, height-field frames and
// bounds). Keeps a reference to the scene, which must outlive it; immutable,
// so thread-safe.
class SceneGeometry {
 public:
  explicit SceneGeometry(const SimScene& scene);

  // Nearest intersection of origin + s * direction with s in (min_s, max_s),
  // or nullopt. direction need not be unit; distances are in units of
  // |direction|.
  std::optional<SurfaceHit> intersect(const Eigen::Vector3d& origin,
                                      const Eigen::Vector3d& direction, double min_s,
                                      double max_s) const;

  const SimScene& scene() const { return scene_; }

  // A height field prepared for exact ray casting: its frame, and the
  // height range of every tile of kHeightFieldTile x kHeightFieldTile cells
  // (a bound of the bilinear surface over the tile), so that a ray skips
  // whole tiles it passes above or below.
  struct HeightFieldFrame {
    const SimHeightField* field;
    Eigen::Vector3d origin, x, y, n;  // n = normal, x, y in-plane (unit)
    double a0, b0;                    // local coordinates of sample (0, 0)
    double extent_a, extent_b;        // mm from sample (0, 0) covered by the surface
    float min_height, max_height;     // mm
    int tiles_x = 0, tiles_y = 0;
    std::vector<float> tile_min, tile_max;  // mm, row-major (tiles_y x tiles_x)
  };
  static constexpr int kHeightFieldTile = 8;  // cells per tile side
  struct PlaneTextureFrame {
    Eigen::Vector3d corner, x, y;  // image corner (-x, -y side) on the plane, unit axes
    double mm_per_px;              // image pixel size on the plane
  };

 private:
  const SimScene& scene_;
  std::vector<Eigen::Vector3d> plane_normals_;  // unit
  std::vector<HeightFieldFrame> height_fields_;
  std::vector<MeshBvh> meshes_;
  std::vector<std::optional<PlaneTextureFrame>> plane_textures_;  // per plane
};

// One-off intersection (prepares the scene on each call: for tests and tools).
std::optional<SurfaceHit> intersectScene(const SimScene& scene, const Eigen::Vector3d& origin,
                                         const Eigen::Vector3d& direction, double min_s,
                                         double max_s);

// Heights (CV_32FC1) of a rough height field as SimRoughness describes, of
// the size SimHeightField::heights_mm must have. Deterministic.
cv::Mat generateRoughHeights(const SimHeightField& field, const SimRoughness& roughness);

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
  // Depth of each pixel's surface point along the camera's optical axis (mm;
  // 0 where no surface), for the camera's defocus blur: filled only when
  // SimConfig::camera_lens has an aperture (f_number > 0), else empty.
  std::vector<float> camera_depth_mm;
  // Per-pixel coefficient of the camera blur (assignCameraBlur), else empty.
  std::vector<float> camera_blur_a;
};

struct SceneView {
  SimGroundTruth ground_truth;  // empty when not asked for
  RenderMaps maps;
};

// Undistorted normalized rays (x, y, 1) of every camera pixel, row-major:
// the iterative undistortion done once per camera.
struct CameraRays {
  int width = 0, height = 0;
  std::vector<Eigen::Vector2d> xy;
};
CameraRays computeCameraRays(const pipeline::PinholeModel& camera);

// Ray-casts every camera pixel of `rig` against the scene with the camera at
// `camera_to_scene` (X_scene = camera_to_scene * X_camera; the projector
// moves with the camera). Radiometry from config. Ground truth is in the
// camera's frame and filled only when with_ground_truth.
//
// Without ground truth the maps may be interpolated: pixels are ray-cast
// exactly on a grid of every 8th row and column and at each 8 x 8 block's
// centre; a block whose corners all see the same lit primitive (not a
// checkerboard) and whose centre the bilinear interpolation predicts within
// 0.01 projector px and 0.1 % of the signal is filled by interpolation, any
// other block (silhouettes, shadow edges, texture, strongly curved surfaces)
// pixel by pixel: the fast path of a moving sensor (bench_sim; figures in
// docs/measurements.md).
SceneView computeSceneView(const SimConfig& config, const SceneGeometry& scene,
                           const pipeline::CameraProjectorCalibration& rig, const CameraRays& rays,
                           const Eigen::Isometry3d& camera_to_scene, bool with_ground_truth);
// The same into `view`, reusing its buffers when the sizes match (no page
// faults on a fresh 30 MB per image).
void computeSceneViewInto(const SimConfig& config, const SceneGeometry& scene,
                          const pipeline::CameraProjectorCalibration& rig, const CameraRays& rays,
                          const Eigen::Isometry3d& camera_to_scene, bool with_ground_truth,
                          SceneView& view);

// Depth (mm, along the projector's optical axis) of the first surface each
// projector pixel lights, with the sensor at camera_to_scene (as in
// computeSceneView): CV_32FC1 of the projector's size, 0 where the pixel's
// ray hits nothing. Ray-cast on every `step`-th pixel and interpolated
// bilinearly (the depth only sets a blur width, so a few pixels' error at
// silhouettes do not matter).
cv::Mat projectorDepthMap(const SceneGeometry& scene,
                          const pipeline::CameraProjectorCalibration& rig,
                          const Eigen::Isometry3d& camera_to_scene, int step);

}  // namespace sl::drivers::sim
