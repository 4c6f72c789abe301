// Triangulator against exact ray-scene intersections on a rig shaped like the
// real sensor: 1440x1080 camera, 1824x1140 projector 175 mm to the camera's
// left, turned 12 deg towards the camera axis; fields of view overlap at
// 300-1000 mm.
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numbers>
#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/triangulator.h"

using namespace sl::pipeline;
using Use = TriangulatorOptions::Use;

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

double deg(double d) { return d * std::numbers::pi / 180.0; }

enum class Baseline { kHorizontal, kVertical };

CameraProjectorCalibration makeRig(bool distortion, Baseline baseline = Baseline::kHorizontal) {
  CameraProjectorCalibration c;
  c.camera.width = 1440;
  c.camera.height = 1080;
  c.camera.fx = 2400;
  c.camera.fy = 2395;
  c.camera.cx = 722.4;
  c.camera.cy = 537.9;
  c.projector.width = 1824;
  c.projector.height = 1140;
  c.projector.fx = 2010;
  c.projector.fy = 1995;
  c.projector.cx = 905.3;
  c.projector.cy = 581.7;
  if (distortion) {
    c.camera.distortion = {-0.1, 0.05, 1e-3, -5e-4, 0.0};
    // About 15 px at the projector's corners.
    c.projector.distortion = {0.06, -0.03, -6e-4, 4e-4, 0.0};
  }
  // Projector centre C and orientation in the camera frame; X_p = R (X_c - C).
  Eigen::Vector3d centre;
  Eigen::Matrix3d to_camera;  // columns: projector axes in the camera frame
  if (baseline == Baseline::kHorizontal) {
    centre = {-175.0, 8.0, 4.0};
    to_camera = (Eigen::AngleAxisd(deg(12.0), Eigen::Vector3d::UnitY()) *
                 Eigen::AngleAxisd(deg(-1.0), Eigen::Vector3d::UnitX()))
                    .toRotationMatrix();
  } else {
    centre = {6.0, -175.0, 3.0};
    to_camera = (Eigen::AngleAxisd(deg(-12.0), Eigen::Vector3d::UnitX()) *
                 Eigen::AngleAxisd(deg(1.0), Eigen::Vector3d::UnitY()))
                    .toRotationMatrix();
  }
  c.R = to_camera.transpose();
  c.t = -c.R * centre;
  return c;
}

enum class Scene { kTiltedPlane, kSphere };

// Distance s along the ray r = (x, y, 1) to the scene (X = s r, s = depth).
std::optional<double> intersect(Scene scene, const Eigen::Vector3d& r) {
  if (scene == Scene::kTiltedPlane) {
    // Through (0, 0, 500 mm), tilted ~16 deg about y and ~9 deg about x.
    const Eigen::Vector3d n = Eigen::Vector3d(0.28, -0.15, 1.0).normalized();
    const double denom = n.dot(r);
    if (std::abs(denom) < 1e-12) return std::nullopt;
    return n.dot(Eigen::Vector3d(0, 0, 500)) / denom;
  }
  const Eigen::Vector3d centre(20, -10, 700);
  const double radius = 220;
  // |s r - c|^2 = R^2, nearest root.
  const double a = r.squaredNorm(), b = -2 * r.dot(centre), c = centre.squaredNorm() - radius * radius;
  const double disc = b * b - 4 * a * c;
  if (disc < 0) return std::nullopt;
  return (-b - std::sqrt(disc)) / (2 * a);
}

// Exact projector coordinates (distorted projector px) of the scene point
// seen by each camera pixel, and the points themselves.
struct Truth {
  ProjectorMaps maps;
  std::vector<Eigen::Vector3d> points;  // NaN where the projector does not see it
  int width = 0, height = 0;
};

Truth makeTruth(const CameraProjectorCalibration& rig, Scene scene) {
  Truth truth;
  truth.width = rig.camera.width;
  truth.height = rig.camera.height;
  const cv::Size size(truth.width, truth.height);
  truth.maps.camera_id = "cam0";
  truth.maps.stamp_ns = 1234567;
  truth.maps.up = cv::Mat(size, CV_32FC1, cv::Scalar(kNaN));
  truth.maps.vp = cv::Mat(size, CV_32FC1, cv::Scalar(kNaN));
  truth.maps.offset = cv::Mat(size, CV_32FC1);
  truth.points.assign(std::size_t(truth.width) * truth.height,
                      Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN()));
  for (int v = 0; v < truth.height; ++v) {
    for (int u = 0; u < truth.width; ++u) {
      truth.maps.offset.at<float>(v, u) = float(u + v);
      const Eigen::Vector2d xn = rig.camera.pixelToNormalized({double(u), double(v)});
      const Eigen::Vector3d r(xn.x(), xn.y(), 1.0);
      const std::optional<double> s = intersect(scene, r);
      if (!s || *s <= 0) continue;
      const Eigen::Vector3d x = *s * r;
      const Eigen::Vector3d xp = rig.R * x + rig.t;
      if (xp.z() <= 0) continue;
      const Eigen::Vector2d q = rig.projector.project(xp);
      if (q.x() < -0.5 || q.x() > rig.projector.width - 0.5 || q.y() < -0.5 ||
          q.y() > rig.projector.height - 0.5)
        continue;
      truth.maps.up.at<float>(v, u) = float(q.x());
      truth.maps.vp.at<float>(v, u) = float(q.y());
      truth.points[std::size_t(v) * truth.width + u] = x;
    }
  }
  return truth;
}

struct Errors {
  double max_mm = 0;
  double rms_mm = 0;
  std::size_t compared = 0;
  std::size_t missing = 0;   // truth exists, cloud is NaN
  std::size_t spurious = 0;  // no truth, cloud is finite
};

Errors compare(const PointCloud& cloud, const Truth& truth) {
  Errors e;
  double sum2 = 0;
  for (std::size_t i = 0; i < truth.points.size(); ++i) {
    const PointXYZI& p = cloud.points[i];
    const bool has_truth = std::isfinite(truth.points[i].z());
    const bool has_point = std::isfinite(p.z);
    if (has_truth && !has_point) ++e.missing;
    if (!has_truth && has_point) ++e.spurious;
    if (!has_truth || !has_point) continue;
    const double d = (Eigen::Vector3d(p.x, p.y, p.z) - truth.points[i]).norm();
    e.max_mm = std::max(e.max_mm, d);
    sum2 += d * d;
    ++e.compared;
  }
  e.rms_mm = e.compared ? std::sqrt(sum2 / e.compared) : 0.0;
  return e;
}

TriangulatorOptions optionsFor(Use use, int iterations) {
  TriangulatorOptions o;
  o.use = use;
  o.projector_distortion_iterations = iterations;
  return o;
}

bool sameCloud(const PointCloud& a, const PointCloud& b) {
  if (a.points.size() != b.points.size()) return false;
  for (std::size_t i = 0; i < a.points.size(); ++i) {
    const PointXYZI& p = a.points[i];
    const PointXYZI& q = b.points[i];
    if (std::isnan(p.z) != std::isnan(q.z)) return false;
    if (!std::isnan(p.z) && (p.x != q.x || p.y != q.y || p.z != q.z)) return false;
  }
  return true;
}

}  // namespace

// Columns are tested on the horizontal-baseline rig and rows on the vertical
// one: across the baseline the coordinate barely changes with depth (it runs
// along the epipolar lines), so that pairing is ill-conditioned by design.
struct AxisCase {
  Use use;
  Baseline baseline;
};

TEST_CASE("triangulation is exact for an undistorted rig", "[triangulator]") {
  const Scene scene = GENERATE(Scene::kTiltedPlane, Scene::kSphere);
  const AxisCase axis = GENERATE(AxisCase{Use::kColumns, Baseline::kHorizontal},
                                 AxisCase{Use::kRows, Baseline::kVertical});
  const Use use = axis.use;
  const CameraProjectorCalibration rig = makeRig(false, axis.baseline);
  const Truth truth = makeTruth(rig, scene);
  const Triangulator triangulator(rig, optionsFor(use, 2));
  const PointCloud cloud = triangulator.triangulate(truth.maps);

  REQUIRE(cloud.width == 1440);
  REQUIRE(cloud.height == 1080);
  REQUIRE(cloud.points.size() == 1440u * 1080u);
  CHECK(cloud.frame_id == "cam0");
  CHECK(cloud.stamp_ns == 1234567);
  CHECK(cloud.points[1440 * 3 + 5].intensity == 8.0f);

  const Errors e = compare(cloud, truth);
  CAPTURE(int(scene), int(use), e.max_mm, e.rms_mm, e.compared, e.missing, e.spurious);
  CHECK(e.compared > 400000);
  CHECK(e.missing == 0);
  CHECK(e.spurious == 0);
  CHECK(cloud.validCount() == e.compared);
  // Measured: max 2.4e-4 .. 3.6e-4 mm (plane and sphere; single-precision
  // arithmetic, float storage of the projector coordinate and the output).
  CHECK(e.max_mm < 1e-3);
}

TEST_CASE("projector distortion correction", "[triangulator]") {
  const Scene scene = GENERATE(Scene::kTiltedPlane, Scene::kSphere);
  const AxisCase axis = GENERATE(AxisCase{Use::kColumns, Baseline::kHorizontal},
                                 AxisCase{Use::kRows, Baseline::kVertical});
  const Use use = axis.use;
  const CameraProjectorCalibration rig = makeRig(true, axis.baseline);
  const Truth truth = makeTruth(rig, scene);

  const Errors none = compare(Triangulator(rig, optionsFor(use, 0)).triangulate(truth.maps), truth);
  const Errors one = compare(Triangulator(rig, optionsFor(use, 1)).triangulate(truth.maps), truth);
  const Errors two = compare(Triangulator(rig, optionsFor(use, 2)).triangulate(truth.maps), truth);
  CAPTURE(int(scene), int(use), none.max_mm, none.rms_mm, one.max_mm, one.rms_mm, two.max_mm,
          two.rms_mm, two.compared);
  CHECK(two.compared > 400000);
  CHECK(two.missing == 0);
  CHECK(two.spurious == 0);
  // Measured max (rms) in mm, plane / sphere, columns (horizontal rig):
  //   0 iterations 8.5 (2.4) / 8.8 (2.4); 1 iteration 0.27 (0.056) / 0.19 (0.046);
  //   2 iterations 4.2e-4 / 6.4e-4 (the epipolar form, single precision;
  //   3.2e-4 / 4.4e-4 along the ray; 2.2e-4 / 2.9e-4 in double).
  // Rows (vertical rig): 0 it. 5.3 / 4.5; 1 it. 0.084 / 0.060; 2 it. 4.6e-4 / 5.3e-4
  // (3.7e-4 / 4.1e-4 along the ray).
  // Two iterations reach about the float floor of the undistorted case.
  // (Plain shifting without the secant step left 8e-3 mm after 2 iterations.)
  CHECK(two.max_mm < 1e-3);
  CHECK(one.max_mm > two.max_mm);
  // Ignoring the projector's distortion is clearly worse: the correction is
  // doing the work.
  CHECK(none.max_mm > 0.5);
  CHECK(none.max_mm > 100 * two.max_mm);
}

TEST_CASE("the epipolar projector correction matches the along-ray reference", "[triangulator]") {
  // Both forms solve for the same undistorted coordinate; the epipolar one
  // (the default) forms the ray's epipolar line once per pixel instead of
  // triangulating and projecting the point every iteration. With the
  // shipped 2 iterations their clouds must agree within float noise, and
  // the epipolar form must stay as close to the truth. 1 iteration is the
  // same plain shift in both.
  const Scene scene = GENERATE(Scene::kTiltedPlane, Scene::kSphere);
  const AxisCase axis = GENERATE(AxisCase{Use::kColumns, Baseline::kHorizontal},
                                 AxisCase{Use::kRows, Baseline::kVertical});
  const int iterations = GENERATE(1, 2);
  const CameraProjectorCalibration rig = makeRig(true, axis.baseline);
  const Truth truth = makeTruth(rig, scene);
  TriangulatorOptions o = optionsFor(axis.use, iterations);
  CHECK(o.projector_correction == TriangulatorOptions::ProjectorCorrection::kEpipolar);
  const PointCloud epipolar = Triangulator(rig, o).triangulate(truth.maps);
  o.projector_correction = TriangulatorOptions::ProjectorCorrection::kAlongRay;
  const PointCloud reference = Triangulator(rig, o).triangulate(truth.maps);
  std::size_t compared = 0, mismatched = 0;
  double max_mm = 0;
  for (std::size_t i = 0; i < epipolar.points.size(); ++i) {
    const PointXYZI& p = epipolar.points[i];
    const PointXYZI& q = reference.points[i];
    if (std::isfinite(p.z) != std::isfinite(q.z)) ++mismatched;
    if (!std::isfinite(p.z) || !std::isfinite(q.z)) continue;
    ++compared;
    max_mm = std::max(
        max_mm, double((Eigen::Vector3f(p.x, p.y, p.z) - Eigen::Vector3f(q.x, q.y, q.z)).norm()));
  }
  const Errors e = compare(epipolar, truth);
  CAPTURE(int(scene), int(axis.use), iterations, max_mm, compared, mismatched, e.max_mm);
  CHECK(compared > 400000);
  CHECK(mismatched == 0);
  // Measured max difference, plane / sphere: columns 2.6e-4 / 3.9e-4 mm
  // (1 iteration), 3.5e-4 / 4.6e-4 (2); rows 3.2e-4 / 3.8e-4 (1), 4.5e-4 /
  // 5.2e-4 (2); against the truth with 2 iterations 3.9e-4 .. 6.4e-4 mm.
  // One iteration less (or plain shifts for the Newton step, 8e-3 mm) is
  // far outside the bound.
  CHECK(max_mm < 1e-3);
  if (iterations == 2) CHECK(e.max_mm < 1e-3);
}

TEST_CASE("camera rays from the grid or per pixel", "[triangulator]") {
  // The rays come from a grid where its interpolation stays within 2e-7 of
  // the exact rays: the coarsest grid for an undistorted camera (bilinear is
  // exact), a finer one for moderate distortion, per-pixel rays for a
  // strongly distorted wide-angle lens (grid error measured: 3e-6 at 4 px).
  struct Lens {
    double fx;
    std::array<double, 5> distortion;
    int expected_step;
  };
  const Lens lens =
      GENERATE(Lens{2400, {0, 0, 0, 0, 0}, 16}, Lens{2400, {-0.1, 0.05, 1e-3, -5e-4, 0.0}, 4},
               Lens{1200, {-0.35, 0.15, 0, 0, 0}, 0});
  CameraProjectorCalibration rig = makeRig(true);
  rig.camera.fx = lens.fx;
  rig.camera.fy = lens.fx;
  rig.camera.distortion = lens.distortion;
  const Triangulator triangulator(rig, optionsFor(Use::kColumns, 2));
  CAPTURE(lens.fx, lens.distortion[0]);
  CHECK(triangulator.rayGridStep() == lens.expected_step);
  const Truth truth = makeTruth(rig, Scene::kTiltedPlane);
  const Errors e = compare(triangulator.triangulate(truth.maps), truth);
  CAPTURE(e.max_mm, e.rms_mm, e.compared);
  CHECK(e.compared > 100000);
  CHECK(e.missing == 0);
  CHECK(e.spurious == 0);
  CHECK(e.max_mm < 1e-3);
}

TEST_CASE("one map: the fused row equals the general one", "[triangulator]") {
  // With one map and no projector correction or the epipolar one with up to
  // 2 iterations, AVX-512 CPUs take a fused row (rays, depth and points in
  // one pass); a second map that is all NaN sends the same pixels through
  // the general row passes, which must give the same bits. Grid rays
  // (moderate distortion) and per-pixel rays (wide lens, with a projector
  // k3), both axes, with and without intensity, 0, 1, 2 and 3 (not fused)
  // iterations; a column
  // offset of the cloud start is covered by the scalar lead of the rows.
  const bool wide = GENERATE(false, true);
  const Baseline baseline = GENERATE(Baseline::kHorizontal, Baseline::kVertical);
  const bool with_offset = GENERATE(true, false);
  const int iterations = GENERATE(0, 1, 2, 3);
  CameraProjectorCalibration rig = makeRig(true, baseline);
  if (wide) {
    rig.camera.fx = rig.camera.fy = 1200;
    rig.camera.distortion = {-0.35, 0.15, 0, 0, 0};
    // A projector k3 as well (the fused row has a variant without it).
    rig.projector.distortion[4] = 0.02;
  }
  const Triangulator triangulator(rig, optionsFor(Use::kBest, iterations));
  CHECK(triangulator.rayGridStep() == (wide ? 0 : 4));
  Truth truth = makeTruth(rig, Scene::kSphere);
  if (!with_offset) truth.maps.offset = cv::Mat();
  const bool columns = baseline == Baseline::kHorizontal;
  ProjectorMaps one = truth.maps;
  ProjectorMaps general = truth.maps;
  (columns ? one.vp : one.up) = cv::Mat();
  (columns ? general.vp : general.up).setTo(kNaN);
  const PointCloud fused_cloud = triangulator.triangulate(one);
  const PointCloud general_cloud = triangulator.triangulate(general);
  CAPTURE(wide, columns, with_offset, iterations);
  CHECK(fused_cloud.validCount() > 100000);
  REQUIRE(fused_cloud.points.size() == general_cloud.points.size());
  CHECK(std::memcmp(fused_cloud.points.data(), general_cloud.points.data(),
                    fused_cloud.points.size() * sizeof(PointXYZI)) == 0);
}

TEST_CASE("kBest picks the axis along the baseline and falls back per pixel", "[triangulator]") {
  const CameraProjectorCalibration rig = makeRig(false);
  const Truth truth = makeTruth(rig, Scene::kTiltedPlane);
  const PointCloud columns = Triangulator(rig, optionsFor(Use::kColumns, 0)).triangulate(truth.maps);
  const PointCloud rows = Triangulator(rig, optionsFor(Use::kRows, 0)).triangulate(truth.maps);
  const Triangulator best(rig, optionsFor(Use::kBest, 0));
  CHECK_FALSE(sameCloud(columns, rows));
  CHECK(sameCloud(best.triangulate(truth.maps), columns));

  ProjectorMaps only_rows = truth.maps;
  only_rows.up = cv::Mat();
  CHECK(sameCloud(best.triangulate(only_rows), rows));
  only_rows.up = cv::Mat(truth.maps.vp.size(), CV_32FC1, cv::Scalar(kNaN));
  CHECK(sameCloud(best.triangulate(only_rows), rows));

  // A vertical baseline prefers rows.
  const CameraProjectorCalibration vertical = makeRig(false, Baseline::kVertical);
  const Truth vtruth = makeTruth(vertical, Scene::kTiltedPlane);
  const PointCloud vrows = Triangulator(vertical, optionsFor(Use::kRows, 0)).triangulate(vtruth.maps);
  const PointCloud vbest = Triangulator(vertical, optionsFor(Use::kBest, 0)).triangulate(vtruth.maps);
  CHECK(sameCloud(vbest, vrows));
  const Errors e = compare(vbest, vtruth);
  CHECK(e.compared > 400000);
  CHECK(e.max_mm < 1e-3);
}

TEST_CASE("triangulator invalid points and inputs", "[triangulator]") {
  const CameraProjectorCalibration rig = makeRig(false);
  Truth truth = makeTruth(rig, Scene::kTiltedPlane);

  SECTION("depth limits") {
    TriangulatorOptions o = optionsFor(Use::kColumns, 0);
    o.min_depth_mm = 480;
    o.max_depth_mm = 520;
    const PointCloud cloud = Triangulator(rig, o).triangulate(truth.maps);
    std::size_t inside = 0, wrong = 0;
    for (std::size_t i = 0; i < truth.points.size(); ++i) {
      const double z = truth.points[i].z();
      // 1e-3 mm guard band for the triangulation error at the limits.
      if (!std::isfinite(z) || std::abs(z - 480) < 1e-3 || std::abs(z - 520) < 1e-3) continue;
      const bool expect = z >= 480 && z <= 520;
      inside += expect;
      if (expect != std::isfinite(cloud.points[i].z)) ++wrong;
    }
    CHECK(inside > 10000);
    CHECK(wrong == 0);
  }

  SECTION("a ray parallel to the projector's plane of the column gives NaN") {
    // The column where the camera ray's vanishing point lands: every point of
    // the ray projects there, so depth is undetermined.
    const int u = 700, v = 500;
    const Eigen::Vector2d xn = rig.camera.pixelToNormalized({double(u), double(v)});
    const Eigen::Vector3d vanishing = rig.projector.K() * rig.R * Eigen::Vector3d(xn.x(), xn.y(), 1);
    truth.maps.up.at<float>(v, u) = float(vanishing.x() / vanishing.z());
    truth.maps.up.at<float>(v, u + 1) = kNaN;
    const PointCloud cloud = Triangulator(rig, optionsFor(Use::kColumns, 0)).triangulate(truth.maps);
    CHECK(std::isnan(cloud.points[std::size_t(v) * 1440 + u].z));
    CHECK(std::isnan(cloud.points[std::size_t(v) * 1440 + u + 1].x));
    CHECK(std::isfinite(cloud.points[std::size_t(v) * 1440 + u + 2].z));
  }

  SECTION("malformed maps throw") {
    const Triangulator columns(rig, optionsFor(Use::kColumns, 0));
    const Triangulator rows(rig, optionsFor(Use::kRows, 0));
    ProjectorMaps m = truth.maps;
    m.up = cv::Mat(10, 10, CV_32FC1);
    CHECK_THROWS_WITH(columns.triangulate(m), Catch::Contains("maps.up"));
    m.up = cv::Mat(1080, 1440, CV_64FC1);
    CHECK_THROWS_AS(columns.triangulate(m), std::invalid_argument);
    m.up = cv::Mat();
    CHECK_THROWS_WITH(columns.triangulate(m), Catch::Contains("kColumns"));
    CHECK_NOTHROW(rows.triangulate(m));
    m.vp = cv::Mat();
    CHECK_THROWS_AS(Triangulator(rig, optionsFor(Use::kBest, 0)).triangulate(m),
                    std::invalid_argument);
    m = truth.maps;
    m.offset = cv::Mat();
    const PointCloud no_intensity = columns.triangulate(m);
    CHECK(no_intensity.points[5].intensity == 0.0f);
  }

  SECTION("bad construction throws") {
    TriangulatorOptions o;
    o.min_depth_mm = 0;
    CHECK_THROWS_AS(Triangulator(rig, o), std::invalid_argument);
    o = TriangulatorOptions{};
    o.projector_distortion_iterations = -1;
    CHECK_THROWS_AS(Triangulator(rig, o), std::invalid_argument);
    CameraProjectorCalibration bad = rig;
    bad.camera.width = 0;
    CHECK_THROWS_AS(Triangulator(bad, {}), std::invalid_argument);
  }
}

TEST_CASE("render, decode and triangulate a tilted plane", "[triangulator][decoder]") {
  // Round trip through the real decoder: 16-bit frames rendered from the exact
  // projector coordinates (dark where the projector does not reach).
  const CameraProjectorCalibration rig = makeRig(true);
  const Truth truth = makeTruth(rig, Scene::kTiltedPlane);
  PhaseShift33Pattern pattern;
  pattern.fringes = 16;
  std::vector<cv::Mat> frames;
  for (int f = 0; f < pattern.frameCount(); ++f) {
    cv::Mat image(1080, 1440, CV_16UC1);
    for (int v = 0; v < 1080; ++v) {
      for (int u = 0; u < 1440; ++u) {
        const float up = truth.maps.up.at<float>(v, u);
        const double lit = std::isnan(up) ? 0.5 : patternIntensity(pattern, f, up, 0);
        image.at<std::uint16_t>(v, u) = std::uint16_t(std::lround(4000 + 40000 * lit));
      }
    }
    frames.push_back(image);
  }
  const ProjectorMaps maps = PhaseShift33Decoder(pattern, {}).decode(frames, 16);
  const PointCloud cloud = Triangulator(rig, TriangulatorOptions{}).triangulate(maps);
  const Errors e = compare(cloud, truth);
  CAPTURE(e.max_mm, e.rms_mm, e.compared, e.missing, e.spurious);
  // The decoder reports the half-pixel band at the left projector edge as out
  // of range, so a few hundred edge pixels may be missing.
  CHECK(e.missing < 2000);
  CHECK(e.spurious == 0);
  CHECK(e.compared > 400000);
  // 16-bit quantisation: < 2e-3 projector px, times 0.6-1.5 mm/px over
  // the plane's depths. Measured: max 5.8e-4 mm, rms 1.8e-4 mm.
  CHECK(e.max_mm < 0.005);
}

TEST_CASE("band form equals decoding and triangulating full maps", "[triangulator][decoder]") {
  // 8-bit 3+3 frames of the tilted plane; bands of 7 rows (the last one
  // shorter) reused across the scan must give the same cloud, bit for bit.
  const CameraProjectorCalibration rig = makeRig(true);
  const Truth truth = makeTruth(rig, Scene::kTiltedPlane);
  PatternSpec spec;
  spec.name = "band";
  const int iterations = GENERATE(0, 2);
  const auto codec = makeCodec(spec, {});
  std::vector<cv::Mat> frames;
  for (int f = 0; f < spec.frameCount(); ++f) {
    cv::Mat image(1080, 1440, CV_8UC1);
    for (int v = 0; v < 1080; ++v) {
      for (int u = 0; u < 1440; ++u) {
        const float up = truth.maps.up.at<float>(v, u);
        const float vp = truth.maps.vp.at<float>(v, u);
        const double lit = std::isnan(up) ? 0.5 : patternIntensity(spec, f, up, vp);
        image.at<std::uint8_t>(v, u) = std::uint8_t(std::lround(20 + 200 * lit));
      }
    }
    frames.push_back(image);
  }
  const Triangulator triangulator(rig, optionsFor(Use::kBest, iterations));
  const ProjectorMaps maps = codec->decode(frames, 8);
  const PointCloud full = triangulator.triangulate(maps);

  PointCloud banded;
  triangulator.prepareCloud(maps.camera_id, maps.stamp_ns, banded);
  ProjectorMaps band;
  bool maps_equal = true;
  for (int y = 0; y < 1080; y += 7) {
    const int y1 = std::min(y + 7, 1080);
    codec->decodeBand(frames, 8, y, y1, band);
    for (int r = y; r < y1; ++r) {
      maps_equal = maps_equal &&
                   std::equal(maps.status.ptr<std::uint8_t>(r), maps.status.ptr<std::uint8_t>(r) + 1440,
                              band.status.ptr<std::uint8_t>(r - y)) &&
                   std::equal(maps.offset.ptr<float>(r), maps.offset.ptr<float>(r) + 1440,
                              band.offset.ptr<float>(r - y));
    }
    triangulator.triangulateBand(band, y, y1, banded);
  }
  CHECK(band.up.rows == 7);
  CHECK(maps_equal);
  CHECK(full.validCount() > 400000);
  CHECK(sameCloud(full, banded));
  bool intensity_equal = true;
  for (std::size_t i = 0; i < full.points.size(); ++i)
    intensity_equal = intensity_equal && full.points[i].intensity == banded.points[i].intensity;
  CHECK(intensity_equal);

  PointCloud unprepared;
  CHECK_THROWS_AS(triangulator.triangulateBand(band, 0, 7, unprepared), std::invalid_argument);
  CHECK_THROWS_AS(triangulator.triangulateBand(band, 0, 8, banded), std::invalid_argument);
  CHECK_THROWS_AS(codec->decodeBand(frames, 8, 1075, 1081, band), std::invalid_argument);
}
