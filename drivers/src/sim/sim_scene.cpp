#include "sim_scene.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <thread>
#include <vector>
#include <opencv2/core.hpp>

#include "sim_render.h"

namespace sl::drivers::sim {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Keeps `candidate` in `best` when it lies in (min_s, max_s) and is nearer.
void keepNearest(std::optional<SurfaceHit>& best, double candidate, double min_s, double max_s,
                 const Eigen::Vector3d& normal, double albedo, const void* primitive,
                 const SimPlane* plane = nullptr, bool textured = false) {
  if (!(candidate > min_s && candidate < max_s)) return;
  if (best && best->distance <= candidate) return;
  best = SurfaceHit{candidate, normal, albedo, plane, primitive, textured};
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

// A checkerboard plane in the camera frame of the current view.
struct BoardInCamera {
  Eigen::Vector3d n;    // unit normal
  double plane_offset;  // n . X on the plane
  BoardFrame frame;
};

// The albedo a camera pixel sees on a checkerboard plane: the board averaged
// over the pixel's footprint (the parallelogram spanned by the plane points
// of the pixel's edges, 16 x 16 samples), or the point value when no square
// edge comes near the footprint. ray and point in the camera frame.
double footprintAlbedo(const SimPlane& plane, const BoardInCamera& board_cam,
                       const pipeline::PinholeModel& camera, int col, int row,
                       const Eigen::Vector3d& ray, const Eigen::Vector3d& point) {
  const SimCheckerboard& board = *plane.checkerboard;
  const Eigen::Vector3d& n = board_cam.n;
  const BoardFrame& frame = board_cam.frame;
  const Eigen::Vector3d rel = point - frame.origin;
  const double a = rel.dot(frame.x), b = rel.dot(frame.y);
  const double s = board.square_mm;
  // Conservative reach of the footprint (mm): twice the pinhole estimate,
  // which covers the lens's local magnification.
  const double cos_view = std::abs(n.dot(ray.normalized()));
  const double reach = 2.0 * point.z() / std::min(camera.fx, camera.fy) / std::max(cos_view, 0.05);
  const double to_edge_a = std::abs(a - s * std::round(a / s));
  const double to_edge_b = std::abs(b - s * std::round(b / s));
  if (std::min(to_edge_a, to_edge_b) > reach) return boardAlbedoAt(board, plane.albedo, a, b);

  auto boardCoordinates = [&](double u, double v) {
    const Eigen::Vector2d xn = camera.pixelToNormalized({u, v});
    const Eigen::Vector3d r{xn.x(), xn.y(), 1.0};
    const Eigen::Vector3d p = r * (board_cam.plane_offset / n.dot(r)) - frame.origin;
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

// Bilinear sample of a CV_32FC1 image at (x, y) (pixel centres at integers),
// or `outside` beyond the outer pixel centres' half-pixel border.
double sampleTexture(const cv::Mat& image, double x, double y, double outside) {
  if (!(x >= -0.5 && y >= -0.5 && x <= image.cols - 0.5 && y <= image.rows - 0.5)) return outside;
  x = std::clamp(x, 0.0, double(image.cols - 1));
  y = std::clamp(y, 0.0, double(image.rows - 1));
  const int x0 = std::min(int(x), std::max(image.cols - 2, 0));
  const int y0 = std::min(int(y), std::max(image.rows - 2, 0));
  const int x1 = std::min(x0 + 1, image.cols - 1), y1 = std::min(y0 + 1, image.rows - 1);
  const double fx = x - x0, fy = y - y0;
  auto at = [&](int r, int c) { return double(image.at<float>(r, c)); };
  return (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x1)) +
         fy * ((1 - fx) * at(y1, x0) + fx * at(y1, x1));
}

void intersectSphere(const SimSphere& sphere, const Eigen::Vector3d& origin,
                     const Eigen::Vector3d& direction, double min_s, double max_s,
                     std::optional<SurfaceHit>& best) {
  // |origin + s d - c|^2 = r^2  <=>  a s^2 + 2 b s + c0 = 0
  const Eigen::Vector3d oc = origin - sphere.center;
  const double a = direction.squaredNorm();
  const double b = direction.dot(oc);
  const double c0 = oc.squaredNorm() - sphere.radius * sphere.radius;
  const double discriminant = b * b - a * c0;
  if (discriminant < 0.0) return;
  const double root = std::sqrt(discriminant);
  for (double s : {(-b - root) / a, (-b + root) / a}) {
    if (s > min_s && s < max_s) {
      const Eigen::Vector3d point = origin + s * direction;
      keepNearest(best, s, min_s, max_s, (point - sphere.center) / sphere.radius, sphere.albedo,
                  &sphere);
      return;  // the first root in range is the nearer one
    }
  }
}

void intersectCone(const SimCone& cone, const Eigen::Vector3d& origin,
                   const Eigen::Vector3d& direction, double min_s, double max_s,
                   std::optional<SurfaceHit>& best) {
  const Eigen::Vector3d u = cone.axis.normalized();  // base -> apex
  const Eigen::Vector3d apex = cone.base_center + cone.height * u;
  const Eigen::Vector3d v = -u;  // apex -> base
  const double cos2 =
      cone.height * cone.height / (cone.height * cone.height + cone.radius * cone.radius);
  // Lateral surface: ((P - apex) . v)^2 = cos^2 |P - apex|^2, 0 <= (P - apex) . v <= height.
  const Eigen::Vector3d w = origin - apex;
  const double dv = direction.dot(v), wv = w.dot(v);
  const double a = dv * dv - cos2 * direction.squaredNorm();
  const double b = dv * wv - cos2 * direction.dot(w);
  const double c = wv * wv - cos2 * w.squaredNorm();
  if (std::abs(a) > 1e-12) {
    const double discriminant = b * b - a * c;
    if (discriminant >= 0.0) {
      const double root = std::sqrt(discriminant);
      for (double s : {(-b - root) / a, (-b + root) / a}) {
        const Eigen::Vector3d q = w + s * direction;  // P - apex
        const double m = q.dot(v);
        if (m < 0.0 || m > cone.height) continue;  // the mirror cone or beyond the base
        const Eigen::Vector3d normal = (q - v * (q.squaredNorm() / m)).normalized();
        keepNearest(best, s, min_s, max_s, normal, cone.albedo, &cone);
      }
    }
  }
  // Base disk, facing away from the apex.
  const double along = direction.dot(u);
  if (along != 0.0) {
    const double s = (cone.base_center - origin).dot(u) / along;
    if ((origin + s * direction - cone.base_center).squaredNorm() <= cone.radius * cone.radius)
      keepNearest(best, s, min_s, max_s, v, cone.albedo, &cone);
  }
}

void intersectBox(const SimBox& box, const Eigen::Vector3d& origin,
                  const Eigen::Vector3d& direction, double min_s, double max_s,
                  std::optional<SurfaceHit>& best) {
  const Eigen::Vector3d o = box.rotation.transpose() * (origin - box.center);
  const Eigen::Vector3d d = box.rotation.transpose() * direction;
  const Eigen::Vector3d half = 0.5 * box.size_mm;
  double s_near = -std::numeric_limits<double>::infinity();
  double s_far = std::numeric_limits<double>::infinity();
  int axis_near = -1, axis_far = -1;
  for (int k = 0; k < 3; ++k) {
    if (d[k] == 0.0) {
      if (std::abs(o[k]) > half[k]) return;
      continue;
    }
    double s1 = (-half[k] - o[k]) / d[k], s2 = (half[k] - o[k]) / d[k];
    if (s1 > s2) std::swap(s1, s2);
    if (s1 > s_near) s_near = s1, axis_near = k;
    if (s2 < s_far) s_far = s2, axis_far = k;
  }
  if (s_near > s_far || axis_near < 0) return;
  auto faceNormal = [&](int axis, double s) {
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    n[axis] = (o[axis] + s * d[axis]) > 0 ? 1.0 : -1.0;
    return Eigen::Vector3d(box.rotation * n);
  };
  keepNearest(best, s_near, min_s, max_s, faceNormal(axis_near, s_near), box.albedo, &box);
  keepNearest(best, s_far, min_s, max_s, faceNormal(axis_far, s_far), box.albedo, &box);
}

// Walks the cells of a grid (square cells of `size` mm, [0, nx) x [0, ny),
// corner at local coordinates (0, 0)) that the segment (oa + s da, ob + s db),
// s in [s0, s1], crosses, in the order of s (Amanatides-Woo). Calls
// visit(ix, iy, enter, leave) with each cell's sub-interval of s; stops early
// and returns true when visit does. The segment is expected to lie in the
// grid; indices are clamped against rounding at its rim.
template <typename Visit>
bool walkGrid(double oa, double ob, double da, double db, double s0, double s1, double size,
              int nx, int ny, const Visit& visit) {
  const double inf = std::numeric_limits<double>::infinity();
  int ix = std::clamp(static_cast<int>(std::floor((oa + s0 * da) / size)), 0, nx - 1);
  int iy = std::clamp(static_cast<int>(std::floor((ob + s0 * db) / size)), 0, ny - 1);
  const int step_x = da > 0 ? 1 : (da < 0 ? -1 : 0);
  const int step_y = db > 0 ? 1 : (db < 0 ? -1 : 0);
  // s where the ray leaves cell index i along one axis.
  auto leaving = [&](int i, int step, double o, double d) {
    if (step == 0) return inf;
    return ((step > 0 ? i + 1 : i) * size - o) / d;
  };
  double s = s0;
  for (;;) {
    const double sx = leaving(ix, step_x, oa, da), sy = leaving(iy, step_y, ob, db);
    const double leave = std::max(s, std::min({sx, sy, s1}));
    if (visit(ix, iy, s, leave)) return true;
    if (leave >= s1) return false;
    if (sx <= sy)
      ix += step_x;
    else
      iy += step_y;
    if (ix < 0 || ix >= nx || iy < 0 || iy >= ny) return false;
    s = leave;
  }
}

// The first s in [s0, s1] where the ray goes from above the bilinear patch of
// cell (ix, iy) to on or below it, or a negative number. Local coordinates:
// a, b in mm from sample (0, 0), h along the normal; the ray is
// (oa, ob, oh) + s (da, db, dh). Along the ray the patch height is quadratic
// in s and the ray's height linear, so the crossing is a root of a quadratic
// (exact, no marching).
double patchCrossing(const cv::Mat& heights, double cell, int ix, int iy, double oa, double ob,
                     double oh, double da, double db, double dh, double s0, double s1) {
  const float* r0 = heights.ptr<float>(iy);
  const float* r1 = heights.ptr<float>(iy + 1);
  const double h00 = r0[ix], h01 = r0[ix + 1], h10 = r1[ix], h11 = r1[ix + 1];
  const double z0 = oh + s0 * dh, z1 = oh + s1 * dh;
  // The patch lies within its corners' range.
  const double lo = std::min(std::min(h00, h01), std::min(h10, h11));
  const double hi = std::max(std::max(h00, h01), std::max(h10, h11));
  if (std::min(z0, z1) > hi + 1e-9 || std::max(z0, z1) < lo - 1e-9) return -1;
  // Cell coordinates (0..1) at s0 and their rates; f(t) = ray height minus
  // patch height at s0 + t: alpha + beta t + gamma t^2.
  const double px = (oa + s0 * da) / cell - ix, py = (ob + s0 * db) / cell - iy;
  const double qx = da / cell, qy = db / cell;
  const double gx = h01 - h00, gy = h10 - h00, k = h00 - h01 - h10 + h11;
  const double alpha = z0 - (h00 + gx * px + gy * py + k * px * py);
  const double beta = dh - (gx * qx + gy * qy + k * (px * qy + py * qx));
  const double gamma = -k * qx * qy;
  const double span = s1 - s0;
  // Roots a hair outside [0, span] are taken (and clamped): a crossing on a
  // cell boundary must not fall between two cells by rounding.
  const double eps = 1e-9 * (1.0 + std::abs(s1));
  double roots[2];
  int count = 0;
  if (std::abs(gamma) * span * span <= 1e-14 * (std::abs(alpha) + std::abs(beta) * span)) {
    if (beta != 0.0) roots[count++] = -alpha / beta;
  } else {
    const double discriminant = beta * beta - 4.0 * gamma * alpha;
    if (discriminant < 0.0) return -1;
    const double q = -0.5 * (beta + std::copysign(std::sqrt(discriminant), beta));
    roots[count++] = q / gamma;
    if (q != 0.0) roots[count++] = alpha / q;
    if (count == 2 && roots[1] < roots[0]) std::swap(roots[0], roots[1]);
  }
  for (int i = 0; i < count; ++i) {
    const double t = roots[i];
    if (!(t >= -eps && t <= span + eps)) continue;
    // Downwards: f falls through zero (a tangent touch or an upward crossing
    // is no entry into the surface).
    if (beta + 2.0 * gamma * t < 0.0) return s0 + std::clamp(t, 0.0, span);
  }
  return -1;
}

// The ray's first crossing from above the height field to on or below it
// (bilinear surface, only its top side exists): clipped to the field's
// slab and rectangle, walked tile by tile, each tile's part of the ray
// clipped to the tile's height range and walked cell by cell, each cell
// solved exactly (patchCrossing).
void intersectHeightField(const SceneGeometry::HeightFieldFrame& f, const Eigen::Vector3d& origin,
                          const Eigen::Vector3d& direction, double min_s, double max_s,
                          std::optional<SurfaceHit>& best) {
  const SimHeightField& field = *f.field;
  const cv::Mat& heights = field.heights_mm;
  const Eigen::Vector3d o = origin - f.origin;
  // Local coordinates from sample (0, 0).
  const double oa = o.dot(f.x) - f.a0, ob = o.dot(f.y) - f.b0, oh = o.dot(f.n);
  const double da = direction.dot(f.x), db = direction.dot(f.y), dh = direction.dot(f.n);
  double s_lo = min_s, s_hi = best ? std::min(max_s, best->distance) : max_s;
  // Restricts [s_lo, s_hi] to value + s * rate in [lo, hi].
  auto clip = [](double value, double rate, double lo, double hi, double& from, double& to) {
    if (std::abs(rate) < 1e-15) {
      if (value < lo || value > hi) to = from - 1;  // empty
      return;
    }
    double s1 = (lo - value) / rate, s2 = (hi - value) / rate;
    if (s1 > s2) std::swap(s1, s2);
    from = std::max(from, s1);
    to = std::min(to, s2);
  };
  const double margin = 1e-6;
  clip(oh, dh, f.min_height - margin, f.max_height + margin, s_lo, s_hi);
  clip(oa, da, 0.0, f.extent_a, s_lo, s_hi);
  clip(ob, db, 0.0, f.extent_b, s_lo, s_hi);
  if (!(s_lo <= s_hi)) return;
  const double cell = field.cell_mm;
  const int cells_x = heights.cols - 1, cells_y = heights.rows - 1;
  constexpr int kTile = SceneGeometry::kHeightFieldTile;
  double hit = -1;
  walkGrid(oa, ob, da, db, s_lo, s_hi, kTile * cell, f.tiles_x, f.tiles_y,
           [&](int tx, int ty, double t0, double t1) {
             const std::size_t tile = static_cast<std::size_t>(ty) * f.tiles_x + tx;
             clip(oh, dh, f.tile_min[tile] - margin, f.tile_max[tile] + margin, t0, t1);
             if (!(t0 <= t1)) return false;
             return walkGrid(oa, ob, da, db, t0, t1, cell, cells_x, cells_y,
                             [&](int ix, int iy, double c0, double c1) {
                               hit = patchCrossing(heights, cell, ix, iy, oa, ob, oh, da, db, dh,
                                                   c0, c1);
                               return hit >= 0;
                             });
           });
  if (hit < 0) return;
  const double a = oa + hit * da, b = ob + hit * db;
  const int ix = std::clamp(static_cast<int>(std::floor(a / cell)), 0, cells_x - 1);
  const int iy = std::clamp(static_cast<int>(std::floor(b / cell)), 0, cells_y - 1);
  const double fx = std::clamp(a / cell - ix, 0.0, 1.0), fy = std::clamp(b / cell - iy, 0.0, 1.0);
  const float* r0 = heights.ptr<float>(iy);
  const float* r1 = heights.ptr<float>(iy + 1);
  const double h00 = r0[ix], h01 = r0[ix + 1], h10 = r1[ix], h11 = r1[ix + 1];
  const double grad_a = ((1 - fy) * (h01 - h00) + fy * (h11 - h10)) / cell;
  const double grad_b = ((1 - fx) * (h10 - h00) + fx * (h11 - h01)) / cell;
  const Eigen::Vector3d normal = (f.n - grad_a * f.x - grad_b * f.y).normalized();
  double albedo = field.albedo;
  if (!field.albedo_texture.empty()) {
    // Texture columns span the width, rows the length (as the heights).
    const cv::Mat& t = field.albedo_texture;
    albedo = sampleTexture(t, a / field.width_mm * (t.cols - 1), b / field.length_mm * (t.rows - 1),
                           field.albedo);
  }
  keepNearest(best, hit, min_s, max_s, normal, albedo, &field, nullptr,
              !field.albedo_texture.empty());
}

}  // namespace

SceneGeometry::SceneGeometry(const SimScene& scene) : scene_(scene) {
  for (const SimPlane& plane : scene.planes) {
    const Eigen::Vector3d n = plane.normal.normalized();
    plane_normals_.push_back(n);
    if (!plane.texture) {
      plane_textures_.emplace_back();
      continue;
    }
    const SimPlaneTexture& t = *plane.texture;
    PlaneTextureFrame f;
    f.x = (t.x_axis - n * n.dot(t.x_axis)).normalized();
    f.y = f.x.cross(n);
    f.mm_per_px = t.width_mm / t.albedo.cols;
    const Eigen::Vector3d center = t.center - n * n.dot(t.center - plane.point);
    // The image's corner; pixel c's centre lies c + 0.5 pixels from it.
    f.corner = center - f.x * (0.5 * t.width_mm) - f.y * (0.5 * f.mm_per_px * t.albedo.rows);
    plane_textures_.push_back(f);
  }
  for (const SimHeightField& field : scene.height_fields) {
    HeightFieldFrame f;
    f.field = &field;
    f.n = field.normal.normalized();
    f.x = (field.x_axis - f.n * f.n.dot(field.x_axis)).normalized();
    f.y = f.n.cross(f.x);
    f.origin = field.origin;
    f.a0 = -0.5 * field.width_mm;
    f.b0 = -0.5 * field.length_mm;
    const cv::Mat& h = field.heights_mm;
    // The surface spans the samples (a width that is not a whole number of
    // cells ends at the last sample, or inside the last cell).
    f.extent_a = std::min(field.width_mm, (h.cols - 1) * field.cell_mm);
    f.extent_b = std::min(field.length_mm, (h.rows - 1) * field.cell_mm);
    double lo = 0, hi = 0;
    cv::minMaxLoc(h, &lo, &hi);
    f.min_height = static_cast<float>(lo);
    f.max_height = static_cast<float>(hi);
    // Tile ranges over the samples of each tile's cells (shared edges included).
    f.tiles_x = (h.cols - 1 + kHeightFieldTile - 1) / kHeightFieldTile;
    f.tiles_y = (h.rows - 1 + kHeightFieldTile - 1) / kHeightFieldTile;
    f.tile_min.assign(static_cast<std::size_t>(f.tiles_x) * f.tiles_y, 0.0f);
    f.tile_max.assign(f.tile_min.size(), 0.0f);
    for (int ty = 0; ty < f.tiles_y; ++ty)
      for (int tx = 0; tx < f.tiles_x; ++tx) {
        const int c0 = tx * kHeightFieldTile, r0 = ty * kHeightFieldTile;
        const int c1 = std::min(c0 + kHeightFieldTile, h.cols - 1);
        const int r1 = std::min(r0 + kHeightFieldTile, h.rows - 1);
        cv::minMaxLoc(h(cv::Range(r0, r1 + 1), cv::Range(c0, c1 + 1)), &lo, &hi);
        const std::size_t i = static_cast<std::size_t>(ty) * f.tiles_x + tx;
        f.tile_min[i] = static_cast<float>(lo);
        f.tile_max[i] = static_cast<float>(hi);
      }
    height_fields_.push_back(f);
  }
  for (const SimMesh& mesh : scene.meshes) meshes_.emplace_back(mesh);
}

std::optional<SurfaceHit> SceneGeometry::intersect(const Eigen::Vector3d& origin,
                                                   const Eigen::Vector3d& direction, double min_s,
                                                   double max_s) const {
  std::optional<SurfaceHit> best;
  for (std::size_t i = 0; i < scene_.planes.size(); ++i) {
    const SimPlane& plane = scene_.planes[i];
    const Eigen::Vector3d& n = plane_normals_[i];
    const double along = n.dot(direction);
    if (along == 0.0) continue;  // ray parallel to the plane
    const double s = n.dot(plane.point - origin) / along;
    keepNearest(best, s, min_s, max_s, n, plane.albedo, &plane, &plane);
  }
  if (best && best->plane && best->plane->texture) {
    const auto index = static_cast<std::size_t>(best->plane - scene_.planes.data());
    const PlaneTextureFrame& f = *plane_textures_[index];
    const Eigen::Vector3d rel = origin + best->distance * direction - f.corner;
    best->albedo = sampleTexture(best->plane->texture->albedo, rel.dot(f.x) / f.mm_per_px - 0.5,
                                 rel.dot(f.y) / f.mm_per_px - 0.5, best->plane->albedo);
    best->textured = true;
  }
  for (const SimSphere& sphere : scene_.spheres)
    intersectSphere(sphere, origin, direction, min_s, max_s, best);
  for (const SimCone& cone : scene_.cones)
    intersectCone(cone, origin, direction, min_s, max_s, best);
  for (const SimBox& box : scene_.boxes) intersectBox(box, origin, direction, min_s, max_s, best);
  for (const HeightFieldFrame& f : height_fields_)
    intersectHeightField(f, origin, direction, min_s, max_s, best);
  for (const MeshBvh& mesh : meshes_) {
    double s = 0;
    Eigen::Vector3d normal;
    if (mesh.intersect(origin, direction, min_s, best ? best->distance : max_s, s, normal))
      keepNearest(best, s, min_s, max_s, normal, mesh.mesh().albedo, &mesh.mesh());
  }
  return best;
}

std::optional<SurfaceHit> intersectScene(const SimScene& scene, const Eigen::Vector3d& origin,
                                         const Eigen::Vector3d& direction, double min_s,
                                         double max_s) {
  return SceneGeometry(scene).intersect(origin, direction, min_s, max_s);
}

cv::Mat generateRoughHeights(const SimHeightField& field, const SimRoughness& roughness) {
  const int cols = static_cast<int>(std::lround(field.width_mm / field.cell_mm)) + 1;
  const int rows = static_cast<int>(std::lround(field.length_mm / field.cell_mm)) + 1;
  cv::Mat noise(rows, cols, CV_32FC1);
  NormalSource normals(mix64(roughness.seed ^ 0x5eedf00dull));
  for (int r = 0; r < rows; ++r) normals.fill(noise.ptr<float>(r), cols);
  cv::Mat spectrum;
  cv::dft(noise, spectrum, cv::DFT_COMPLEX_OUTPUT);
  // Amplitude filter: flat below k0 = 1 / correlation length, k^-(1 + H) above.
  const double k0 = 1.0 / roughness.correlation_length_mm;
  for (int r = 0; r < rows; ++r) {
    const double ky = (r <= rows / 2 ? r : r - rows) / (rows * field.cell_mm);
    auto* row = spectrum.ptr<cv::Vec2f>(r);
    for (int c = 0; c < cols; ++c) {
      const double kx = (c <= cols / 2 ? c : c - cols) / (cols * field.cell_mm);
      const double k = std::hypot(kx, ky);
      const double gain = k <= k0 ? 1.0 : std::pow(k / k0, -(1.0 + roughness.hurst));
      row[c] *= static_cast<float>(gain);
    }
  }
  cv::Mat heights;
  cv::dft(spectrum, heights, cv::DFT_INVERSE | cv::DFT_REAL_OUTPUT | cv::DFT_SCALE);
  cv::Scalar mean, stddev;
  cv::meanStdDev(heights, mean, stddev);
  heights -= mean[0];
  if (stddev[0] > 0) heights *= roughness.rms_mm / stddev[0];
  return heights;
}

CameraRays computeCameraRays(const pipeline::PinholeModel& camera) {
  CameraRays rays;
  rays.width = camera.width;
  rays.height = camera.height;
  rays.xy.resize(static_cast<std::size_t>(camera.width) * camera.height);
  for (int row = 0; row < camera.height; ++row)
    for (int col = 0; col < camera.width; ++col)
      rays.xy[static_cast<std::size_t>(row) * camera.width + col] =
          camera.pixelToNormalized({double(col), double(row)});
  return rays;
}

SceneView computeSceneView(const SimConfig& config, const SceneGeometry& scene,
                           const pipeline::CameraProjectorCalibration& rig, const CameraRays& rays,
                           const Eigen::Isometry3d& camera_to_scene, bool with_ground_truth) {
  SceneView view;
  computeSceneViewInto(config, scene, rig, rays, camera_to_scene, with_ground_truth, view);
  return view;
}

namespace {

// Runs body(i) for i in [0, n) on up to hardware_concurrency() threads
// (contiguous chunks; the calling thread takes the first). Ray casting a
// moving view is the simulator's cost (about 2 s per 1440 x 1080 image of a
// 1.4 M-triangle mesh on one core); the pixels are independent.
template <typename Body>
void parallelFor(int n, const Body& body) {
  const int threads =
      std::clamp(static_cast<int>(std::thread::hardware_concurrency()), 1, std::max(1, n / 4));
  if (threads <= 1) {
    for (int i = 0; i < n; ++i) body(i);
    return;
  }
  std::vector<std::thread> pool;
  auto chunk = [&](int t) {
    const int begin = static_cast<int>(static_cast<long long>(n) * t / threads);
    const int end = static_cast<int>(static_cast<long long>(n) * (t + 1) / threads);
    for (int i = begin; i < end; ++i) body(i);
  };
  for (int t = 1; t < threads; ++t) pool.emplace_back(chunk, t);
  chunk(0);
  for (std::thread& thread : pool) thread.join();
}

}  // namespace

void computeSceneViewInto(const SimConfig& config, const SceneGeometry& scene,
                          const pipeline::CameraProjectorCalibration& rig, const CameraRays& rays,
                          const Eigen::Isometry3d& camera_to_scene, bool with_ground_truth,
                          SceneView& view) {
  const int width = rig.camera.width, height = rig.camera.height;
  const int proj_width = rig.projector.width, proj_height = rig.projector.height;
  const Eigen::Matrix3d rotation = camera_to_scene.linear();
  const Eigen::Vector3d camera_center = camera_to_scene.translation();  // scene frame
  // Projector pose relative to the scene: X_p = R_ps * X_scene + t_ps.
  const Eigen::Matrix3d R_ps = rig.R * rotation.transpose();
  const Eigen::Vector3d t_ps = rig.t - R_ps * camera_center;
  const Eigen::Vector3d projector_center = -R_ps.transpose() * t_ps;  // scene frame, mm
  const double projector_field_radius2 = monotonicFieldRadius2(rig.projector);

  SimGroundTruth& gt = view.ground_truth;
  gt = {};
  if (with_ground_truth) {
    gt.depth_mm = cv::Mat(height, width, CV_32FC1, cv::Scalar(kNaN));
    gt.xyz_mm = cv::Mat(height, width, CV_32FC3, cv::Scalar(kNaN, kNaN, kNaN));
    gt.up = cv::Mat(height, width, CV_32FC1, cv::Scalar(kNaN));
    gt.vp = cv::Mat(height, width, CV_32FC1, cv::Scalar(kNaN));
    gt.lit = cv::Mat(height, width, CV_8UC1, cv::Scalar(0));
  }

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
  const bool camera_depths = config.camera_lens.f_number > 0;
  if (camera_depths)
    maps.camera_depth_mm.assign(n, 0.0f);
  else
    maps.camera_depth_mm.clear();

  const double inf = std::numeric_limits<double>::infinity();
  const SimScene& planes_scene = scene.scene();
  std::vector<std::optional<BoardInCamera>> boards;  // per plane, in this camera's frame
  const Eigen::Isometry3d scene_to_camera = camera_to_scene.inverse();
  for (const SimPlane& plane : planes_scene.planes) {
    if (!plane.checkerboard) {
      boards.emplace_back();
      continue;
    }
    const BoardFrame f = boardFrame(plane);
    BoardInCamera b;
    b.n = scene_to_camera.linear() * plane.normal.normalized();
    b.frame = {scene_to_camera * f.origin, scene_to_camera.linear() * f.x,
               scene_to_camera.linear() * f.y};
    b.plane_offset = b.n.dot(scene_to_camera * plane.point);
    boards.push_back(b);
  }
  // The exact computation of one pixel; writes the ground truth if asked.
  struct Sample {
    const void* primitive = nullptr;  // nullptr: no surface
    bool textured = false;            // checkerboard: never interpolated
    bool lit = false;
    float ambient = 0, per_level = 0;
    double up = 0, vp = 0;
    double camera_z = 0;  // mm along the camera's optical axis (0: no surface)
  };
  auto castPixel = [&](int col, int row) {
    Sample out;
    const std::size_t i = static_cast<std::size_t>(row) * width + col;
    const Eigen::Vector2d& xn = rays.xy[i];
    const Eigen::Vector3d ray{xn.x(), xn.y(), 1.0};  // camera frame; s is the depth z (mm)
    const Eigen::Vector3d ray_scene = rotation * ray;
    const std::optional<SurfaceHit> hit = scene.intersect(camera_center, ray_scene, 0.0, inf);
    if (!hit) return out;
    out.primitive = hit->primitive;
    const Eigen::Vector3d point_camera = hit->distance * ray;
    out.camera_z = point_camera.z();
    const Eigen::Vector3d point = camera_center + hit->distance * ray_scene;  // scene frame
    if (with_ground_truth) {
      gt.depth_mm.ptr<float>(row)[col] = static_cast<float>(point_camera.z());
      gt.xyz_mm.ptr<cv::Vec3f>(row)[col] =
          cv::Vec3f(float(point_camera.x()), float(point_camera.y()), float(point_camera.z()));
    }
    double albedo = hit->albedo;
    out.textured = hit->textured;
    if (hit->plane && hit->plane->checkerboard) {
      const auto index = static_cast<std::size_t>(hit->plane - planes_scene.planes.data());
      albedo =
          footprintAlbedo(*hit->plane, *boards[index], rig.camera, col, row, ray, point_camera);
      out.textured = true;
    }
    out.ambient = static_cast<float>(config.ambient_dn * albedo);

    // The side of the surface the camera sees.
    const Eigen::Vector3d normal = hit->normal.dot(ray_scene) > 0 ? -hit->normal : hit->normal;
    const Eigen::Vector3d point_in_projector = rig.R * point_camera + rig.t;
    if (point_in_projector.z() <= 0.0) return out;  // behind the projector
    // Beyond the lens's field the distortion polynomial folds back into
    // the image; such points are not lit.
    const double xp = point_in_projector.x() / point_in_projector.z();
    const double yp = point_in_projector.y() / point_in_projector.z();
    if (xp * xp + yp * yp >= projector_field_radius2) return out;
    const Eigen::Vector2d projector_px = rig.projector.project(point_in_projector);
    const double up = projector_px.x(), vp = projector_px.y();
    // A projector pixel covers [c - 0.5, c + 0.5) around its centre c.
    if (!(up >= -0.5 && up < proj_width - 0.5 && vp >= -0.5 && vp < proj_height - 0.5)) return out;
    const Eigen::Vector3d to_projector = projector_center - point;
    const double distance = to_projector.norm();
    const double cos_incidence = normal.dot(to_projector) / distance;
    if (cos_incidence <= 0.0) return out;  // lit from behind
    // Shadow: anything between the point and the projector centre (1 um
    // tolerance at the point itself).
    if (scene.intersect(point, to_projector, 1e-3 / distance, 1.0)) return out;

    const double falloff = config.reference_distance_mm / distance;
    const double shading = albedo * cos_incidence * falloff * falloff;
    out.per_level = static_cast<float>(config.projector_brightness_dn * shading / 255.0);
    out.lit = true;
    out.up = up;
    out.vp = vp;
    if (with_ground_truth) {
      gt.up.ptr<float>(row)[col] = static_cast<float>(up);
      gt.vp.ptr<float>(row)[col] = static_cast<float>(vp);
      gt.lit.ptr<std::uint8_t>(row)[col] = 255;
    }
    return out;
  };
  auto store = [&](int col, int row, const Sample& sample) {
    const std::size_t i = static_cast<std::size_t>(row) * width + col;
    maps.ambient_dn[i] = sample.ambient;
    if (camera_depths) maps.camera_depth_mm[i] = static_cast<float>(sample.camera_z);
    if (!sample.lit) return;
    maps.projector_dn_per_level[i] = sample.per_level;
    // Bilinear sampling at the pixel centres, clamped to the image edge.
    const double u_clamped = std::clamp(sample.up, 0.0, double(proj_width - 1));
    const double v_clamped = std::clamp(sample.vp, 0.0, double(proj_height - 1));
    const int x0 = std::min(int(std::floor(u_clamped)), std::max(proj_width - 2, 0));
    const int y0 = std::min(int(std::floor(v_clamped)), std::max(proj_height - 2, 0));
    maps.texel_index[i] = y0 * proj_width + x0;
    maps.weight_x[i] = static_cast<float>(u_clamped - x0);
    maps.weight_y[i] = static_cast<float>(v_clamped - y0);
  };

  if (with_ground_truth) {
    parallelFor(height, [&](int row) {
      for (int col = 0; col < width; ++col) store(col, row, castPixel(col, row));
    });
    return;
  }

  // Interpolated fast path (see the header).
  constexpr int kBlock = 8;
  auto gridLines = [](int size) {
    std::vector<int> lines;
    for (int x = 0; x < size - 1; x += kBlock) lines.push_back(x);
    lines.push_back(size - 1);
    return lines;
  };
  const std::vector<int> grid_cols = gridLines(width), grid_rows = gridLines(height);
  const std::size_t gw = grid_cols.size();
  std::vector<Sample> grid(gw * grid_rows.size());
  parallelFor(static_cast<int>(grid_rows.size()), [&](int gy) {
    for (std::size_t gx = 0; gx < gw; ++gx)
      grid[gy * gw + gx] = castPixel(grid_cols[gx], grid_rows[gy]);
  });
  auto blend = [](const Sample& s00, const Sample& s01, const Sample& s10, const Sample& s11,
                  double fx, double fy) {
    auto mix = [&](double a, double b, double c, double d) {
      return (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * d);
    };
    Sample s = s00;
    s.ambient = static_cast<float>(mix(s00.ambient, s01.ambient, s10.ambient, s11.ambient));
    s.per_level =
        static_cast<float>(mix(s00.per_level, s01.per_level, s10.per_level, s11.per_level));
    s.up = mix(s00.up, s01.up, s10.up, s11.up);
    s.vp = mix(s00.vp, s01.vp, s10.vp, s11.vp);
    s.camera_z = mix(s00.camera_z, s01.camera_z, s10.camera_z, s11.camera_z);
    return s;
  };
  parallelFor(static_cast<int>(grid_rows.size()) - 1, [&](int block_row) {
    const std::size_t gy = static_cast<std::size_t>(block_row);
    const int r0 = grid_rows[gy], r1 = grid_rows[gy + 1];
    const int row_end = gy + 2 == grid_rows.size() ? r1 + 1 : r1;  // last block: its far edge
    for (std::size_t gx = 0; gx + 1 < gw; ++gx) {
      const int c0 = grid_cols[gx], c1 = grid_cols[gx + 1];
      const int col_end = gx + 2 == gw ? c1 + 1 : c1;
      const Sample& s00 = grid[gy * gw + gx];
      const Sample& s01 = grid[gy * gw + gx + 1];
      const Sample& s10 = grid[(gy + 1) * gw + gx];
      const Sample& s11 = grid[(gy + 1) * gw + gx + 1];
      bool smooth = s00.primitive && s00.lit && !s00.textured;
      for (const Sample* s : {&s01, &s10, &s11})
        smooth = smooth && s->primitive == s00.primitive && s->lit;
      if (smooth && (c1 - c0 > 1 || r1 - r0 > 1)) {
        const int cc = (c0 + c1) / 2, rc = (r0 + r1) / 2;
        const Sample exact = castPixel(cc, rc);
        const Sample predicted = blend(s00, s01, s10, s11, double(cc - c0) / std::max(c1 - c0, 1),
                                       double(rc - r0) / std::max(r1 - r0, 1));
        smooth = exact.primitive == s00.primitive && exact.lit &&
                 std::abs(exact.up - predicted.up) < 0.01 &&
                 std::abs(exact.vp - predicted.vp) < 0.01 &&
                 std::abs(exact.per_level - predicted.per_level) <= 1e-3 * exact.per_level &&
                 std::abs(exact.ambient - predicted.ambient) <= 1e-3 * exact.ambient + 1e-6f;
      }
      if (smooth) {
        // Bilinear fill: per row, the values at the block's left and right
        // edges, then linear steps along the row (the corners included).
        const float inv_w = 1.0f / float(std::max(c1 - c0, 1));
        const float u_max = float(proj_width - 1), v_max = float(proj_height - 1);
        for (int row = r0; row < row_end; ++row) {
          const double fy = double(row - r0) / std::max(r1 - r0, 1);
          const Sample left = blend(s00, s01, s10, s11, 0.0, fy);
          const Sample right = blend(s00, s01, s10, s11, 1.0, fy);
          const float a0 = left.ambient, da = (right.ambient - left.ambient) * inv_w;
          const float p0 = left.per_level, dp = (right.per_level - left.per_level) * inv_w;
          const float u0 = float(left.up), du = float(right.up - left.up) * inv_w;
          const float v0 = float(left.vp), dv = float(right.vp - left.vp) * inv_w;
          const float zc0 = float(left.camera_z),
                      dzc = float(right.camera_z - left.camera_z) * inv_w;
          const std::size_t base = static_cast<std::size_t>(row) * width;
          for (int col = c0; col < col_end; ++col) {
            const float k = float(col - c0);
            const std::size_t i = base + col;
            maps.ambient_dn[i] = a0 + k * da;
            maps.projector_dn_per_level[i] = p0 + k * dp;
            const float u = std::clamp(u0 + k * du, 0.0f, u_max);
            const float v = std::clamp(v0 + k * dv, 0.0f, v_max);
            const int x0 = std::min(int(u), std::max(proj_width - 2, 0));
            const int y0 = std::min(int(v), std::max(proj_height - 2, 0));
            maps.texel_index[i] = y0 * proj_width + x0;
            maps.weight_x[i] = u - float(x0);
            maps.weight_y[i] = v - float(y0);
            if (camera_depths) maps.camera_depth_mm[i] = zc0 + k * dzc;
          }
        }
        continue;
      }
      for (int row = r0; row < row_end; ++row)
        for (int col = c0; col < col_end; ++col) {
          const bool on_grid = (col == c0 || col == c1) && (row == r0 || row == r1);
          store(col, row,
                on_grid ? grid[(gy + (row == r1)) * gw + gx + (col == c1)] : castPixel(col, row));
        }
    }
  });
}

cv::Mat projectorDepthMap(const SceneGeometry& scene,
                          const pipeline::CameraProjectorCalibration& rig,
                          const Eigen::Isometry3d& camera_to_scene, int step) {
  const int width = rig.projector.width, height = rig.projector.height;
  // Projector frame -> scene frame: X_scene = camera_to_scene * R^T (X_p - t).
  const Eigen::Matrix3d to_scene = camera_to_scene.linear() * rig.R.transpose();
  const Eigen::Vector3d origin = camera_to_scene * (-rig.R.transpose() * rig.t);
  const double inf = std::numeric_limits<double>::infinity();
  const int cols = (width - 1 + step - 1) / step + 1, rows = (height - 1 + step - 1) / step + 1;
  cv::Mat coarse(rows, cols, CV_32FC1);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const double u = std::min(c * step, width - 1), v = std::min(r * step, height - 1);
      const Eigen::Vector2d xn = rig.projector.pixelToNormalized({u, v});
      // Direction (x, y, 1) in the projector frame: s is the projector depth.
      const std::optional<SurfaceHit> hit =
          scene.intersect(origin, to_scene * Eigen::Vector3d(xn.x(), xn.y(), 1.0), 0.0, inf);
      coarse.at<float>(r, c) = hit ? static_cast<float>(hit->distance) : 0.0f;
    }
  cv::Mat depth(height, width, CV_32FC1);
  for (int v = 0; v < height; ++v) {
    const double y = double(v) / step;
    const int r0 = std::min(int(y), rows - 2 < 0 ? 0 : rows - 2);
    const int r1 = std::min(r0 + 1, rows - 1);
    const float fy = static_cast<float>(std::clamp(y - r0, 0.0, 1.0));
    float* out = depth.ptr<float>(v);
    for (int u = 0; u < width; ++u) {
      const double x = double(u) / step;
      const int c0 = std::min(int(x), cols - 2 < 0 ? 0 : cols - 2);
      const int c1 = std::min(c0 + 1, cols - 1);
      const float fx = static_cast<float>(std::clamp(x - c0, 0.0, 1.0));
      const float d00 = coarse.at<float>(r0, c0), d01 = coarse.at<float>(r0, c1);
      const float d10 = coarse.at<float>(r1, c0), d11 = coarse.at<float>(r1, c1);
      // Where a corner misses the scene, take the nearest corner (no blend with 0).
      if (d00 <= 0 || d01 <= 0 || d10 <= 0 || d11 <= 0) {
        out[u] = (fy < 0.5f ? (fx < 0.5f ? d00 : d01) : (fx < 0.5f ? d10 : d11));
        continue;
      }
      out[u] = (1 - fy) * ((1 - fx) * d00 + fx * d01) + fy * ((1 - fx) * d10 + fx * d11);
    }
  }
  return depth;
}

}  // namespace sl::drivers::sim

namespace sl::drivers {

void appendTransformed(SimScene& scene, const SimScene& group, const Eigen::Isometry3d& pose) {
  const Eigen::Matrix3d r = pose.linear();
  for (const SimPlane& source : group.planes) {
    SimPlane& p = scene.planes.emplace_back(source);
    p.point = pose * p.point;
    p.normal = r * p.normal;
    if (p.checkerboard) {
      p.checkerboard->origin = pose * p.checkerboard->origin;
      p.checkerboard->x_axis = r * p.checkerboard->x_axis;
      p.checkerboard->y_axis = r * p.checkerboard->y_axis;
    }
    if (p.texture) {
      p.texture->center = pose * p.texture->center;
      p.texture->x_axis = r * p.texture->x_axis;
    }
  }
  for (SimSphere s : group.spheres) {
    s.center = pose * s.center;
    scene.spheres.push_back(s);
  }
  for (SimCone c : group.cones) {
    c.base_center = pose * c.base_center;
    c.axis = r * c.axis;
    scene.cones.push_back(c);
  }
  for (SimBox b : group.boxes) {
    b.center = pose * b.center;
    b.rotation = r * b.rotation;
    scene.boxes.push_back(b);
  }
  for (SimHeightField h : group.height_fields) {
    h.origin = pose * h.origin;
    h.normal = r * h.normal;
    h.x_axis = r * h.x_axis;
    scene.height_fields.push_back(h);
  }
  for (SimMesh m : group.meshes) {
    m.pose = pose * m.pose;
    scene.meshes.push_back(std::move(m));
  }
}

}  // namespace sl::drivers
