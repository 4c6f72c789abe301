#include "sim_scene.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>

namespace sl::drivers::sim {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Keeps `candidate` in `best` when it lies in (min_s, max_s) and is nearer.
void keepNearest(std::optional<SurfaceHit>& best, double candidate, double min_s, double max_s,
                 const Eigen::Vector3d& normal, double albedo, const SimPlane* plane = nullptr) {
  if (!(candidate > min_s && candidate < max_s)) return;
  if (best && best->distance <= candidate) return;
  best = SurfaceHit{candidate, normal, albedo, plane};
}

// In-plane frame of a checkerboard: origin on the plane, orthonormal axes.
struct BoardFrame {
  Eigen::Vector3d origin, x, y;
};

BoardFrame boardFrame(const SimPlane& plane) {
  const SimCheckerboard& b = *plane.checkerboard;
  const Eigen::Vector3d n = plane.normal.normalized();
  BoardFrame f;
  f.origin = b.origin - n * n.dot(b.origin - plane.point);
  f.x = (b.x_axis - n * n.dot(b.x_axis)).normalized();
  f.y = (b.y_axis - n * n.dot(b.y_axis) - f.x * f.x.dot(b.y_axis)).normalized();
  return f;
}

// Albedo at board coordinates (a, b) (mm along the board axes from the
// origin); square (i, j) covers [i s, (i + 1) s) x [j s, (j + 1) s).
double boardAlbedoAt(const SimCheckerboard& board, double margin_albedo, double a, double b) {
  const double i = std::floor(a / board.square_mm), j = std::floor(b / board.square_mm);
  if (i < -1 || i > board.cols - 1 || j < -1 || j > board.rows - 1) return margin_albedo;
  return (static_cast<long long>(i + j) & 1) == 0 ? board.dark_albedo : board.light_albedo;
}

// The albedo a camera pixel sees on a checkerboard plane: the board averaged
// over the pixel's footprint (the parallelogram spanned by the plane points
// of the pixel's edges, 16 x 16 samples), or the point value when no square
// edge comes near the footprint.
double footprintAlbedo(const SimPlane& plane, const BoardFrame& frame,
                       const pipeline::PinholeModel& camera, int col, int row,
                       const Eigen::Vector3d& ray, const Eigen::Vector3d& point) {
  const SimCheckerboard& board = *plane.checkerboard;
  const Eigen::Vector3d n = plane.normal.normalized();
  const Eigen::Vector3d rel = point - frame.origin;
  const double a = rel.dot(frame.x), b = rel.dot(frame.y);
  const double s = board.square_mm;
  // Conservative reach of the footprint (mm): twice the pinhole estimate,
  // which covers the lens's local magnification.
  const double cos_view = std::abs(n.dot(ray.normalized()));
  const double reach =
      2.0 * point.z() / std::min(camera.fx, camera.fy) / std::max(cos_view, 0.05);
  const double to_edge_a = std::abs(a - s * std::round(a / s));
  const double to_edge_b = std::abs(b - s * std::round(b / s));
  if (std::min(to_edge_a, to_edge_b) > reach) return boardAlbedoAt(board, plane.albedo, a, b);

  const double plane_offset = n.dot(plane.point);
  auto boardCoordinates = [&](double u, double v) {
    const Eigen::Vector2d xn = camera.pixelToNormalized({u, v});
    const Eigen::Vector3d r{xn.x(), xn.y(), 1.0};
    const Eigen::Vector3d p = r * (plane_offset / n.dot(r)) - frame.origin;
    return Eigen::Vector2d(p.dot(frame.x), p.dot(frame.y));
  };
  const Eigen::Vector2d centre(a, b);
  const Eigen::Vector2d du = 2.0 * (boardCoordinates(col + 0.5, row) - centre);
  const Eigen::Vector2d dv = 2.0 * (boardCoordinates(col, row + 0.5) - centre);
  constexpr int kSamples = 16;
  double sum = 0;
  for (int k = 0; k < kSamples; ++k) {
    const double fu = (k + 0.5) / kSamples - 0.5;
    for (int l = 0; l < kSamples; ++l) {
      const double fv = (l + 0.5) / kSamples - 0.5;
      const Eigen::Vector2d q = centre + fu * du + fv * dv;
      sum += boardAlbedoAt(board, plane.albedo, q.x(), q.y());
    }
  }
  return sum / (kSamples * kSamples);
}

// Squared normalized radius up to which the radial distortion of `model`
// is monotonic (the distorted radius grows with the undistorted one):
// d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] > 0. Infinity if it is everywhere
// up to r = 10 (84 degrees off axis).
double monotonicFieldRadius2(const pipeline::PinholeModel& model) {
  const auto& d = model.distortion;
  constexpr double kStep = 1e-3, kMaxRadius = 10.0;
  for (double r = kStep; r <= kMaxRadius; r += kStep) {
    const double r2 = r * r;
    if (1.0 + r2 * (3.0 * d[0] + r2 * (5.0 * d[1] + r2 * 7.0 * d[4])) <= 0.0) return r2;
  }
  return std::numeric_limits<double>::infinity();
}

}  // namespace

std::optional<SurfaceHit> intersectScene(const SimScene& scene, const Eigen::Vector3d& origin,
                                         const Eigen::Vector3d& direction, double min_s,
                                         double max_s) {
  std::optional<SurfaceHit> best;
  for (const SimPlane& plane : scene.planes) {
    const Eigen::Vector3d n = plane.normal.normalized();
    const double along = n.dot(direction);
    if (along == 0.0) continue;  // ray parallel to the plane
    const double s = n.dot(plane.point - origin) / along;
    keepNearest(best, s, min_s, max_s, n, plane.albedo, &plane);
  }
  for (const SimSphere& sphere : scene.spheres) {
    // |origin + s d - c|^2 = r^2  <=>  a s^2 + 2 b s + c0 = 0
    const Eigen::Vector3d oc = origin - sphere.center;
    const double a = direction.squaredNorm();
    const double b = direction.dot(oc);
    const double c0 = oc.squaredNorm() - sphere.radius * sphere.radius;
    const double discriminant = b * b - a * c0;
    if (discriminant < 0.0) continue;
    const double root = std::sqrt(discriminant);
    for (double s : {(-b - root) / a, (-b + root) / a}) {
      if (s > min_s && s < max_s) {
        const Eigen::Vector3d point = origin + s * direction;
        keepNearest(best, s, min_s, max_s, (point - sphere.center) / sphere.radius, sphere.albedo);
        break;  // the first root in range is the nearer one
      }
    }
  }
  return best;
}

SceneView computeSceneView(const SimConfig& config) {
  const pipeline::CameraProjectorCalibration& rig = config.rig;
  const int width = rig.camera.width, height = rig.camera.height;
  const int proj_width = rig.projector.width, proj_height = rig.projector.height;
  const Eigen::Vector3d projector_center = -rig.R.transpose() * rig.t;  // camera frame, mm
  const double projector_field_radius2 = monotonicFieldRadius2(rig.projector);

  SceneView view;
  SimGroundTruth& gt = view.ground_truth;
  gt.depth_mm = cv::Mat(height, width, CV_32FC1, cv::Scalar(kNaN));
  gt.xyz_mm = cv::Mat(height, width, CV_32FC3, cv::Scalar(kNaN, kNaN, kNaN));
  gt.up = cv::Mat(height, width, CV_32FC1, cv::Scalar(kNaN));
  gt.vp = cv::Mat(height, width, CV_32FC1, cv::Scalar(kNaN));
  gt.lit = cv::Mat(height, width, CV_8UC1, cv::Scalar(0));

  RenderMaps& maps = view.maps;
  const std::size_t n = static_cast<std::size_t>(width) * height;
  maps.width = width;
  maps.height = height;
  maps.texture_width = proj_width;
  maps.ambient_dn.assign(n, 0.0f);
  maps.projector_dn_per_level.assign(n, 0.0f);
  maps.texel_index.assign(n, 0);
  maps.weight_x.assign(n, 0.0f);
  maps.weight_y.assign(n, 0.0f);

  const double inf = std::numeric_limits<double>::infinity();
  std::vector<std::optional<BoardFrame>> board_frames;  // per plane
  for (const SimPlane& plane : config.scene.planes)
    board_frames.push_back(plane.checkerboard ? std::optional(boardFrame(plane)) : std::nullopt);
  for (int row = 0; row < height; ++row) {
    auto* depth_row = gt.depth_mm.ptr<float>(row);
    auto* xyz_row = gt.xyz_mm.ptr<cv::Vec3f>(row);
    auto* up_row = gt.up.ptr<float>(row);
    auto* vp_row = gt.vp.ptr<float>(row);
    auto* lit_row = gt.lit.ptr<std::uint8_t>(row);
    for (int col = 0; col < width; ++col) {
      const std::size_t i = static_cast<std::size_t>(row) * width + col;
      const Eigen::Vector2d xn = rig.camera.pixelToNormalized({double(col), double(row)});
      const Eigen::Vector3d ray{xn.x(), xn.y(), 1.0};  // s along it is the depth z (mm)
      const std::optional<SurfaceHit> hit =
          intersectScene(config.scene, Eigen::Vector3d::Zero(), ray, 0.0, inf);
      if (!hit) continue;
      const Eigen::Vector3d point = hit->distance * ray;
      depth_row[col] = static_cast<float>(point.z());
      xyz_row[col] = cv::Vec3f(float(point.x()), float(point.y()), float(point.z()));
      double albedo = hit->albedo;
      if (hit->plane && hit->plane->checkerboard) {
        const auto index = static_cast<std::size_t>(hit->plane - config.scene.planes.data());
        albedo = footprintAlbedo(*hit->plane, *board_frames[index], rig.camera, col, row, ray,
                                 point);
      }
      maps.ambient_dn[i] = static_cast<float>(config.ambient_dn * albedo);

      // The side of the surface the camera sees.
      const Eigen::Vector3d normal = hit->normal.dot(ray) > 0 ? -hit->normal : hit->normal;
      const Eigen::Vector3d point_in_projector = rig.R * point + rig.t;
      if (point_in_projector.z() <= 0.0) continue;  // behind the projector
      // Beyond the lens's field the distortion polynomial folds back into
      // the image; such points are not lit.
      const double xp = point_in_projector.x() / point_in_projector.z();
      const double yp = point_in_projector.y() / point_in_projector.z();
      if (xp * xp + yp * yp >= projector_field_radius2) continue;
      const Eigen::Vector2d projector_px = rig.projector.project(point_in_projector);
      const double up = projector_px.x(), vp = projector_px.y();
      // A projector pixel covers [c - 0.5, c + 0.5) around its centre c.
      if (!(up >= -0.5 && up < proj_width - 0.5 && vp >= -0.5 && vp < proj_height - 0.5)) continue;
      const Eigen::Vector3d to_projector = projector_center - point;
      const double distance = to_projector.norm();
      const double cos_incidence = normal.dot(to_projector) / distance;
      if (cos_incidence <= 0.0) continue;  // lit from behind
      // Shadow: anything between the point and the projector centre (1 um
      // tolerance at the point itself).
      if (intersectScene(config.scene, point, to_projector, 1e-3 / distance, 1.0)) continue;

      const double falloff = config.reference_distance_mm / distance;
      const double shading = albedo * cos_incidence * falloff * falloff;
      maps.projector_dn_per_level[i] =
          static_cast<float>(config.projector_brightness_dn * shading / 255.0);
      // Bilinear sampling at the pixel centres, clamped to the image edge.
      const double u_clamped = std::clamp(up, 0.0, double(proj_width - 1));
      const double v_clamped = std::clamp(vp, 0.0, double(proj_height - 1));
      const int x0 = std::min(int(std::floor(u_clamped)), std::max(proj_width - 2, 0));
      const int y0 = std::min(int(std::floor(v_clamped)), std::max(proj_height - 2, 0));
      maps.texel_index[i] = y0 * proj_width + x0;
      maps.weight_x[i] = static_cast<float>(u_clamped - x0);
      maps.weight_y[i] = static_cast<float>(v_clamped - y0);

      up_row[col] = static_cast<float>(up);
      vp_row[col] = static_cast<float>(vp);
      lit_row[col] = 255;
    }
  }
  return view;
}

}  // namespace sl::drivers::sim
