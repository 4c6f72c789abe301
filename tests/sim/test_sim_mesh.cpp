// Tests of the simulator's triangle meshes (PLY files, BVH ray casting,
// ground truth and projector shadows) and composites: a mesh of a box must
// be indistinguishable from the analytic box, a finely tessellated sphere
// close to the analytic sphere, a group placed by a pose the same as its
// members placed one by one, and a height field the same as its samples
// meshed (the two ray casters agree).
#include <unistd.h>

#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <opencv2/core.hpp>
#include <string>

#include "sl/drivers/sim.h"
#include "support/sim_rig.h"
#include "support/icosphere.h"
#include "support/relief.h"

namespace {

using sl::drivers::SimBox;
using sl::drivers::SimConfig;
using sl::drivers::SimMesh;
using sl::drivers::SimPlane;
using sl::drivers::SimScene;
using sl::drivers::SimSphere;
using sl::drivers::SimulatedSensor;

constexpr double kPi = std::numbers::pi;

SimConfig baseConfig() {
  SimConfig c = sl::test::simConfig33("3+3");
  c.gain_dn_per_electron = 0;
  c.read_noise_dn = 0;
  return c;
}

// The 8 corners and 12 outward-wound triangles of a box of `size` centred
// at the origin of its own frame.
SimMesh boxMesh(const Eigen::Vector3d& size) {
  SimMesh m;
  for (int k = 0; k < 8; ++k)
    m.vertices.emplace_back(static_cast<float>((k & 1 ? 0.5 : -0.5) * size.x()),
                            static_cast<float>((k & 2 ? 0.5 : -0.5) * size.y()),
                            static_cast<float>((k & 4 ? 0.5 : -0.5) * size.z()));
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.push_back({q[0], q[1], q[2]});
    m.triangles.push_back({q[0], q[2], q[3]});
  }
  return m;
}

std::string tempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("sl_sim_mesh_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

// Compares two sensors' ground truth: validity, lit mask and depth.
struct GroundTruthDifference {
  int valid_mismatch = 0, lit_mismatch = 0, valid = 0, lit = 0;
  double max_depth_error = 0;
};
GroundTruthDifference compare(const SimulatedSensor& a, const SimulatedSensor& b) {
  GroundTruthDifference d;
  const auto& ga = a.groundTruth();
  const auto& gb = b.groundTruth();
  for (int r = 0; r < ga.depth_mm.rows; ++r)
    for (int c = 0; c < ga.depth_mm.cols; ++c) {
      const float za = ga.depth_mm.at<float>(r, c), zb = gb.depth_mm.at<float>(r, c);
      if (std::isnan(za) != std::isnan(zb)) {
        ++d.valid_mismatch;
        continue;
      }
      if (std::isnan(za)) continue;
      ++d.valid;
      d.max_depth_error = std::max(d.max_depth_error, double(std::abs(za - zb)));
      const bool la = ga.lit.at<std::uint8_t>(r, c) != 0, lb = gb.lit.at<std::uint8_t>(r, c) != 0;
      d.lit_mismatch += la != lb;
      d.lit += la;
    }
  return d;
}

}  // namespace

TEST_CASE("PLY: ascii and binary little-endian, extra properties skipped, polygons split",
          "[sim][mesh]") {
  const SimMesh box = boxMesh({40, 30, 20});
  const std::string ascii = tempPath("box_ascii.ply");
  {
    std::ofstream out(ascii);
    out << "ply\nformat ascii 1.0\ncomment a box in metres\nelement vertex 8\n"
           "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
           "element face 12\nproperty list uchar int vertex_indices\nend_header\n";
    for (const auto& v : box.vertices)
      out << v.x() / 1000 << " " << v.y() / 1000 << " " << v.z() / 1000 << " 200\n";
    for (const auto& t : box.triangles) out << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
  }
  const std::string binary = tempPath("box_binary.ply");
  {
    // Quads, double coordinates, a normal per vertex and an int count type.
    std::ofstream out(binary, std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty double x\n"
           "property double y\nproperty double z\nproperty float nx\nelement face 6\n"
           "property list int uint vertex_index\nproperty uchar flags\nend_header\n";
    for (const auto& v : box.vertices) {
      const double xyz[3] = {v.x(), v.y(), v.z()};
      const float nx = 0;
      out.write(reinterpret_cast<const char*>(xyz), sizeof(xyz));
      out.write(reinterpret_cast<const char*>(&nx), sizeof(nx));
    }
    for (std::size_t q = 0; q < 12; q += 2) {
      const std::int32_t n = 4;
      const std::uint32_t quad[4] = {
          std::uint32_t(box.triangles[q][0]), std::uint32_t(box.triangles[q][1]),
          std::uint32_t(box.triangles[q][2]), std::uint32_t(box.triangles[q + 1][2])};
      const std::uint8_t flags = 7;
      out.write(reinterpret_cast<const char*>(&n), sizeof(n));
      out.write(reinterpret_cast<const char*>(quad), sizeof(quad));
      out.write(reinterpret_cast<const char*>(&flags), sizeof(flags));
    }
  }
  const SimMesh from_ascii = sl::drivers::loadPlyMesh(ascii, 1000.0);
  const SimMesh from_binary = sl::drivers::loadPlyMesh(binary);
  for (const SimMesh* m : {&from_ascii, &from_binary}) {
    REQUIRE(m->vertices.size() == 8);
    REQUIRE(m->triangles.size() == 12);
    for (std::size_t i = 0; i < 8; ++i) CHECK((m->vertices[i] - box.vertices[i]).norm() < 1e-4f);
    CHECK(m->triangles == box.triangles);
  }

  const std::string broken = tempPath("broken.ply");
  {
    std::ofstream out(broken);
    out << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
           "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
           "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n";
  }
  CHECK_THROWS_WITH(sl::drivers::loadPlyMesh(broken),
                    Catch::Contains("out of range") && Catch::Contains(broken));
  CHECK_THROWS_WITH(sl::drivers::loadPlyMesh(tempPath("missing.ply")),
                    Catch::Contains("cannot be opened"));
  // Sizes and kinds checked before reading or allocating: a device, a
  // directory, a header claiming more entries than the file holds, an index
  // beyond int32.
  CHECK_THROWS_WITH(sl::drivers::loadPlyMesh("/dev/zero"),
                    Catch::Contains("/dev/zero") && Catch::Contains("not a regular file"));
  CHECK_THROWS_WITH(sl::drivers::loadPlyMesh("/tmp"), Catch::Contains("is a directory"));
  const std::string huge = tempPath("huge.ply");
  {
    std::ofstream out(huge);
    out << "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000000\nproperty float x\n"
           "property float y\nproperty float z\nend_header\n";
  }
  CHECK_THROWS_WITH(sl::drivers::loadPlyMesh(huge),
                    Catch::Contains("declares 4000000000000 entries") && Catch::Contains(huge));
  {
    std::ofstream out(broken);
    out << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
           "property float z\nelement face 1\nproperty list uchar double vertex_indices\nend_header\n"
           "0 0 0\n1 0 0\n0 1 0\n3 0 1 1e300\n";
  }
  CHECK_THROWS_WITH(sl::drivers::loadPlyMesh(broken), Catch::Contains("vertex index"));
  for (const std::string& path : {ascii, binary, broken, huge}) std::remove(path.c_str());
}

TEST_CASE("mesh of a box = the analytic box: depth, validity and projector shadow", "[sim][mesh]") {
  // A tilted box in front of a wall, casting a projector shadow on it.
  Eigen::Matrix3d rotation = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()))
                                 .toRotationMatrix();
  const Eigen::Vector3d center{-20, 10, 480}, size{60, 50, 40};
  SimConfig analytic = baseConfig();
  analytic.scene.planes = {SimPlane{{0, 0, 620}, {0, 0, -1}, 0.8}};
  analytic.scene.boxes = {SimBox{center, size, rotation, 0.7}};
  SimConfig meshed = baseConfig();
  meshed.scene.planes = analytic.scene.planes;
  SimMesh mesh = boxMesh(size);
  mesh.pose.linear() = rotation;
  mesh.pose.translation() = center;
  mesh.albedo = 0.7;
  meshed.scene.meshes = {mesh};
  const auto a = SimulatedSensor::create(analytic);
  const auto b = SimulatedSensor::create(meshed);
  const GroundTruthDifference d = compare(*a, *b);
  const int shadowed = d.valid - d.lit;
  INFO("valid " << d.valid << ", shadowed " << shadowed << ", validity mismatches "
                << d.valid_mismatch << ", lit mismatches " << d.lit_mismatch << ", max depth error "
                << d.max_depth_error << " mm");
  CHECK(shadowed > 20000);       // the box shadows a visible part of the wall
  CHECK(d.valid_mismatch == 0);  // the wall is behind everything
  CHECK(d.lit_mismatch < 50);    // at most a few pixels exactly on a shadow edge
  CHECK(d.max_depth_error < 1e-3);
  // Rendered images agree too (same albedo and normals).
  const cv::Mat ia = a->render("3+3", 1, 0), ib = b->render("3+3", 1, 0);
  CHECK(cv::countNonZero(cv::abs(ia - ib) > 1) < 100);
}

TEST_CASE("plaster height field = its samples as a mesh, within the bilinear-triangle gap",
          "[sim][mesh][heightfield]") {
  // sl_eval wall's surface (a 1 mm height field) used to be ray-cast as this
  // mesh through the BVH; the height field's own (exact bilinear) ray
  // casting must render the same images. The two surfaces differ by at most
  // `gap` in height (the bilinear patch against the two triangles of a cell)
  // and in their normals by the patch's twist.
  const sl::drivers::SimHeightField wall = sl::test::plasterWall(150, 110, 450);
  const double gap = sl::test::bilinearTriangleGap(wall.heights_mm);
  SimConfig field_config = baseConfig();
  field_config.scene.height_fields = {wall};
  SimConfig mesh_config = baseConfig();
  mesh_config.scene.meshes = {sl::test::heightFieldMesh(wall)};
  for (SimConfig* c : {&field_config, &mesh_config}) {
    // A moving sensor: render() ray-casts each image's own pose through the
    // interpolating fast path, as the wall experiment does.
    c->motion.velocity_mm_s = {12.5, 0, 0};
    c->camera_lens.f_number = 0;  // no blur: pixel-wise comparison
    c->projector_lens.f_number = 0;
  }
  const auto a = SimulatedSensor::create(field_config);
  const auto b = SimulatedSensor::create(mesh_config);
  const GroundTruthDifference d = compare(*a, *b);
  // Projector coordinates where both are lit.
  const auto& ga = a->groundTruth();
  const auto& gb = b->groundTruth();
  double worst_up = 0, worst_vp = 0;
  for (int r = 0; r < ga.up.rows; ++r)
    for (int c = 0; c < ga.up.cols; ++c) {
      if (!ga.lit.at<std::uint8_t>(r, c) || !gb.lit.at<std::uint8_t>(r, c)) continue;
      worst_up = std::max(worst_up, double(std::abs(ga.up.at<float>(r, c) - gb.up.at<float>(r, c))));
      worst_vp = std::max(worst_vp, double(std::abs(ga.vp.at<float>(r, c) - gb.vp.at<float>(r, c))));
    }
  INFO("valid " << d.valid << ", lit " << d.lit << ", validity mismatches " << d.valid_mismatch
                << ", lit mismatches " << d.lit_mismatch << ", max depth difference "
                << d.max_depth_error << " mm (bilinear-triangle gap " << gap
                << " mm), projector px difference " << worst_up << " / " << worst_vp);
  CHECK(d.valid > 400000);        // the wall fills a third of the view
  CHECK(d.valid_mismatch < 20);   // only at the rim
  CHECK(d.lit_mismatch < 20);     // no projector shadows on this relief
  // Along a ray within 25 deg of the normal: gap / cos(25 deg), float vertices.
  CHECK(d.max_depth_error < gap / std::cos(25 * kPi / 180) + 1e-3);
  CHECK(gap < 0.02);
  CHECK(worst_up < 0.05);
  CHECK(worst_vp < 0.05);
  // The rendered (moving, interpolated) images agree to the shading
  // difference of the normals: a few DN at most, 0.2 DN on average (a
  // high-frequency and a unit-frequency frame of 3+3).
  for (int frame : {1, 4}) {
    const cv::Mat ia = a->render("3+3", frame, 0), ib = b->render("3+3", frame, 0);
    cv::Mat diff;
    cv::absdiff(ia, ib, diff);
    double worst = 0;
    cv::minMaxLoc(diff, nullptr, &worst);
    const double mean = cv::mean(diff)[0];
    const int over_two = cv::countNonZero(diff > 2);
    INFO("frame " << frame << ": mean |difference| " << mean << " DN, max " << worst
                  << " DN, pixels beyond 2 DN " << over_two);
    CHECK(mean < 0.2);
    CHECK(worst <= 8);
    CHECK(over_two < 500);
  }
}

TEST_CASE("tessellated sphere (20480 triangles) within the tessellation error of the sphere",
          "[sim][mesh]") {
  const double radius = 60;
  const Eigen::Vector3d center{30, -10, 520};
  SimConfig config = baseConfig();
  SimMesh sphere = sl::test::unitIcosphere(5);
  REQUIRE(sphere.triangles.size() == 20480);
  // Every surface point lies between the sphere and the nearest triangle plane.
  double sagitta = 0;
  for (const auto& t : sphere.triangles) {
    const Eigen::Vector3d a = sphere.vertices[std::size_t(t[0])].cast<double>();
    const Eigen::Vector3d b = sphere.vertices[std::size_t(t[1])].cast<double>();
    const Eigen::Vector3d c = sphere.vertices[std::size_t(t[2])].cast<double>();
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    sagitta = std::max(sagitta, radius * (1 - std::abs(n.dot(a))));
  }
  for (auto& v : sphere.vertices) v *= static_cast<float>(radius);
  sphere.pose.translation() = center;
  config.scene.meshes = {sphere};
  config.scene.planes = {SimPlane{{0, 0, 700}, {0, 0, -1}, 0.8}};
  const auto sensor = SimulatedSensor::create(config);
  const cv::Mat& xyz = sensor->groundTruth().xyz_mm;
  double worst = 0;
  int on_sphere = 0;
  for (int r = 0; r < xyz.rows; r += 3)
    for (int c = 0; c < xyz.cols; c += 3) {
      const cv::Vec3f p = xyz.at<cv::Vec3f>(r, c);
      if (std::isnan(p[2]) || p[2] > 650) continue;  // the wall
      const double distance = (Eigen::Vector3d(p[0], p[1], p[2]) - center).norm();
      worst = std::max(worst, std::abs(distance - radius));
      ++on_sphere;
    }
  INFO("pixels on the sphere " << on_sphere << ", worst |distance - r| " << worst
                               << " mm (sagitta bound " << sagitta << ")");
  CHECK(on_sphere > 10000);
  CHECK(worst <= sagitta + 1e-4);
}

TEST_CASE("composite: a group placed by one pose = its members placed one by one",
          "[sim][mesh][composite]") {
  SimScene group;
  group.spheres = {SimSphere{{0, 0, 0}, 25, 0.6}};
  group.boxes = {SimBox{{50, 0, 10}, {20, 30, 40}, Eigen::Matrix3d::Identity(), 0.7}};
  SimMesh mesh = boxMesh({15, 15, 15});
  mesh.pose.translation() = Eigen::Vector3d(-45, 5, 0);
  group.meshes = {mesh};
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() =
      Eigen::AngleAxisd(0.5, Eigen::Vector3d(0.2, 1, 0.1).normalized()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(10, -5, 500);

  SimConfig grouped = baseConfig();
  grouped.scene.planes = {SimPlane{{0, 0, 650}, {0, 0.1, -1}, 0.8}};
  sl::drivers::appendTransformed(grouped.scene, group, pose);
  REQUIRE(grouped.scene.spheres.size() == 1);
  REQUIRE(grouped.scene.meshes.size() == 1);

  SimConfig placed = baseConfig();
  placed.scene.planes = grouped.scene.planes;
  placed.scene.spheres = {SimSphere{pose * Eigen::Vector3d(0, 0, 0), 25, 0.6}};
  placed.scene.boxes = {
      SimBox{pose * Eigen::Vector3d(50, 0, 10), {20, 30, 40}, pose.linear(), 0.7}};
  SimMesh moved = mesh;
  moved.pose = pose * mesh.pose;
  placed.scene.meshes = {moved};

  const GroundTruthDifference d =
      compare(*SimulatedSensor::create(grouped), *SimulatedSensor::create(placed));
  CHECK(d.valid > 1000000);
  CHECK(d.valid_mismatch == 0);
  CHECK(d.lit_mismatch == 0);
  CHECK(d.max_depth_error < 1e-6);
}

namespace {

// A smooth albedo image: a ramp along x times a slow wave along y, in [0.1, 0.9].
cv::Mat smoothAlbedo(int cols, int rows) {
  cv::Mat image(rows, cols, CV_32FC1);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      image.at<float>(r, c) = static_cast<float>(
          0.1 + 0.8 * (double(c) / (cols - 1)) * (0.75 + 0.25 * std::cos(2 * kPi * r / rows)));
  return image;
}

// Bilinear sample with pixel centres at integers (x, y inside the image).
double bilinear(const cv::Mat& image, double x, double y) {
  const int x0 = std::clamp(int(std::floor(x)), 0, image.cols - 2);
  const int y0 = std::clamp(int(std::floor(y)), 0, image.rows - 2);
  const double fx = std::clamp(x - x0, 0.0, 1.0), fy = std::clamp(y - y0, 0.0, 1.0);
  auto at = [&](int r, int c) { return double(image.at<float>(r, c)); };
  return (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) +
         fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1));
}

// Renders ambient light only (projector dark): the image is ambient * albedo.
SimConfig ambientOnly() {
  SimConfig c = baseConfig();
  c.projector_brightness_dn = 0;
  c.ambient_dn = 200;
  c.bit_depth = 16;
  c.camera_lens.f_number = 0;  // no blur: each pixel sees its own point's albedo
  return c;
}

}  // namespace

TEST_CASE("textured albedo on a plane and on a height field: each pixel sees its point's texel",
          "[sim][texture]") {
  const cv::Mat texture = smoothAlbedo(64, 48);
  SECTION("plane") {
    SimConfig c = ambientOnly();
    SimPlane plane{{0, 0, 600}, {0.1, 0, -1}, 0.05};
    sl::drivers::SimPlaneTexture t;
    t.albedo = texture;
    t.center = {10, 5, 600};
    t.x_axis = {1, 0.2, 0};
    t.width_mm = 160;
    plane.texture = t;
    c.scene.planes = {plane};
    const auto sensor = SimulatedSensor::create(c);
    const cv::Mat image = sensor->render("3+3", 0, 0);
    const cv::Mat& xyz = sensor->groundTruth().xyz_mm;
    // The frame the header documents: columns along x (in the plane), rows along x cross n.
    const Eigen::Vector3d n = plane.normal.normalized();
    const Eigen::Vector3d x = (t.x_axis - n * n.dot(t.x_axis)).normalized(), y = x.cross(n);
    const double px = t.width_mm / texture.cols;
    const Eigen::Vector3d center = t.center - n * n.dot(t.center - plane.point);
    int inside = 0, outside = 0;
    double worst = 0;
    for (int r = 0; r < image.rows; r += 5)
      for (int col = 0; col < image.cols; col += 5) {
        const cv::Vec3f p = xyz.at<cv::Vec3f>(r, col);
        const Eigen::Vector3d rel = Eigen::Vector3d(p[0], p[1], p[2]) - center;
        const double u = rel.dot(x) / px + texture.cols / 2.0 - 0.5;
        const double v = rel.dot(y) / px + texture.rows / 2.0 - 0.5;
        double albedo = plane.albedo;
        if (u > -0.5 && v > -0.5 && u < texture.cols - 0.5 && v < texture.rows - 0.5) {
          // Away from the border, where the camera pixel straddles it.
          if (u < 0.5 || v < 0.5 || u > texture.cols - 1.5 || v > texture.rows - 1.5) continue;
          albedo = bilinear(texture, u, v);
          ++inside;
        } else {
          ++outside;
        }
        const double expected = 200 * albedo * 65535 / 255;
        worst = std::max(worst, std::abs(image.at<std::uint16_t>(r, col) - expected) / expected);
      }
    INFO("inside " << inside << ", outside " << outside << ", worst relative error " << worst);
    CHECK(inside > 10000);
    CHECK(outside > 10000);
    CHECK(worst < 2e-3);  // float geometry; 16-bit rounding
  }
  SECTION("height field") {
    SimConfig c = ambientOnly();
    sl::drivers::SimHeightField field;
    field.origin = {0, 0, 580};
    field.width_mm = 170;
    field.length_mm = 120;
    field.cell_mm = 1;
    field.heights_mm = cv::Mat(121, 171, CV_32FC1, cv::Scalar(0.0));
    for (int r = 0; r < 121; ++r)
      for (int col = 0; col < 171; ++col)
        field.heights_mm.at<float>(r, col) =
            static_cast<float>(3 * std::sin(col * 0.05) * std::cos(r * 0.07));
    field.albedo_texture = texture;
    c.scene.height_fields = {field};
    const auto sensor = SimulatedSensor::create(c);
    const cv::Mat image = sensor->render("3+3", 0, 0);
    const cv::Mat& xyz = sensor->groundTruth().xyz_mm;
    // Field frame: n = (0, 0, -1), x = (1, 0, 0), y = n x x = (0, -1, 0).
    int inside = 0;
    double worst = 0;
    for (int r = 0; r < image.rows; r += 5)
      for (int col = 0; col < image.cols; col += 5) {
        const cv::Vec3f p = xyz.at<cv::Vec3f>(r, col);
        if (std::isnan(p[2])) continue;
        const double a = p[0] - field.origin.x(), b = -(p[1] - field.origin.y());
        const double u = (a + field.width_mm / 2) / field.width_mm * (texture.cols - 1);
        const double v = (b + field.length_mm / 2) / field.length_mm * (texture.rows - 1);
        if (u < 0.5 || v < 0.5 || u > texture.cols - 1.5 || v > texture.rows - 1.5) continue;
        const double expected = 200 * bilinear(texture, u, v) * 65535 / 255;
        worst = std::max(worst, std::abs(image.at<std::uint16_t>(r, col) - expected) / expected);
        ++inside;
      }
    INFO("inside " << inside << ", worst relative error " << worst);
    CHECK(inside > 10000);
    CHECK(worst < 2e-3);
  }
}
