#include "sim_mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

namespace sl::drivers::sim {

namespace {

constexpr std::int32_t kLeafSize = 4;

// Slab test: the entry parameter of the ray into [lo, hi] if it enters
// before `limit` (and leaves after min_s), else infinity.
double boxEntry(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, const Eigen::Vector3d& origin,
                const Eigen::Vector3d& inverse, double min_s, double limit) {
  double enter = min_s, leave = limit;
  for (int k = 0; k < 3; ++k) {
    double a = (lo[k] - origin[k]) * inverse[k], b = (hi[k] - origin[k]) * inverse[k];
    if (a > b) std::swap(a, b);
    // NaN (0 * inf for a ray in the slab's plane) leaves the bound unchanged.
    enter = a > enter ? a : enter;
    leave = b < leave ? b : leave;
  }
  return enter <= leave ? enter : std::numeric_limits<double>::infinity();
}

}  // namespace

MeshBvh::MeshBvh(const SimMesh& mesh) : mesh_(&mesh) {
  const std::size_t n = mesh.triangles.size();
  std::vector<Eigen::Vector3d> vertices(mesh.vertices.size());
  for (std::size_t i = 0; i < vertices.size(); ++i)
    vertices[i] = mesh.pose * mesh.vertices[i].cast<double>();
  std::vector<Triangle> triangles(n);
  std::vector<Eigen::Vector3d> centroids(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& t = mesh.triangles[i];
    const Eigen::Vector3d& a = vertices[static_cast<std::size_t>(t[0])];
    const Eigen::Vector3d& b = vertices[static_cast<std::size_t>(t[1])];
    const Eigen::Vector3d& c = vertices[static_cast<std::size_t>(t[2])];
    triangles[i] = {a, b - a, c - a};
    centroids[i] = (a + b + c) / 3.0;
  }
  std::vector<std::int32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::int32_t>(i);
  if (n == 0) return;
  nodes_.reserve(2 * n / kLeafSize + 2);
  nodes_.emplace_back();
  build(0, order, 0, static_cast<std::int32_t>(n), centroids, triangles);
  triangles_.resize(n);
  for (std::size_t i = 0; i < n; ++i) triangles_[i] = triangles[static_cast<std::size_t>(order[i])];
}

void MeshBvh::build(std::size_t node, std::vector<std::int32_t>& order, std::int32_t first,
                    std::int32_t count, const std::vector<Eigen::Vector3d>& centroids,
                    const std::vector<Triangle>& triangles) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo, centroid_lo = lo, centroid_hi = hi;
  for (std::int32_t i = first; i < first + count; ++i) {
    const auto k = static_cast<std::size_t>(order[static_cast<std::size_t>(i)]);
    const Triangle& t = triangles[k];
    for (const Eigen::Vector3d& p :
         {t.a, Eigen::Vector3d(t.a + t.ab), Eigen::Vector3d(t.a + t.ac)}) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    centroid_lo = centroid_lo.cwiseMin(centroids[k]);
    centroid_hi = centroid_hi.cwiseMax(centroids[k]);
  }
  // Boxes in float, widened by a float ulp-scale margin so no hit is lost.
  const Eigen::Vector3d pad = Eigen::Vector3d::Constant(1e-5 * (1 + hi.cwiseAbs().maxCoeff()));
  nodes_[node].lo = (lo - pad).cast<float>();
  nodes_[node].hi = (hi + pad).cast<float>();
  const Eigen::Vector3d extent = centroid_hi - centroid_lo;
  int axis = 0;
  extent.maxCoeff(&axis);
  if (count <= kLeafSize || extent[axis] <= 0) {
    nodes_[node].first = first;
    nodes_[node].count = count;
    return;
  }
  const std::int32_t half = count / 2;
  auto begin = order.begin() + first;
  std::nth_element(begin, begin + half, begin + count, [&](std::int32_t x, std::int32_t y) {
    return centroids[static_cast<std::size_t>(x)][axis] <
           centroids[static_cast<std::size_t>(y)][axis];
  });
  const auto left = static_cast<std::int32_t>(nodes_.size());
  nodes_[node].first = left;
  nodes_[node].count = 0;
  nodes_.emplace_back();
  nodes_.emplace_back();
  build(static_cast<std::size_t>(left), order, first, half, centroids, triangles);
  build(static_cast<std::size_t>(left) + 1, order, first + half, count - half, centroids,
        triangles);
}

bool MeshBvh::intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                        double min_s, double max_s, double& s, Eigen::Vector3d& normal) const {
  if (nodes_.empty()) return false;
  const Eigen::Vector3d inverse = direction.cwiseInverse();
  double best = max_s;
  std::int32_t best_triangle = -1;
  std::array<std::int32_t, 64> stack{};
  int top = 0;
  if (boxEntry(nodes_[0].lo, nodes_[0].hi, origin, inverse, min_s, best) ==
      std::numeric_limits<double>::infinity())
    return false;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[static_cast<std::size_t>(stack[--top])];
    if (node.count > 0) {
      // Moller-Trumbore, two-sided.
      for (std::int32_t i = node.first; i < node.first + node.count; ++i) {
        const Triangle& t = triangles_[static_cast<std::size_t>(i)];
        const Eigen::Vector3d p = direction.cross(t.ac);
        const double det = t.ab.dot(p);
        if (std::abs(det) < 1e-300) continue;
        const double inv_det = 1.0 / det;
        const Eigen::Vector3d q = origin - t.a;
        const double u = q.dot(p) * inv_det;
        if (u < 0.0 || u > 1.0) continue;
        const Eigen::Vector3d r = q.cross(t.ab);
        const double v = direction.dot(r) * inv_det;
        if (v < 0.0 || u + v > 1.0) continue;
        const double hit = t.ac.dot(r) * inv_det;
        if (hit > min_s && hit < best) {
          best = hit;
          best_triangle = i;
        }
      }
      continue;
    }
    // Inner node: push the farther child first so the nearer is visited first.
    const std::int32_t left = node.first, right = node.first + 1;
    const double enter_left =
        boxEntry(nodes_[static_cast<std::size_t>(left)].lo,
                 nodes_[static_cast<std::size_t>(left)].hi, origin, inverse, min_s, best);
    const double enter_right =
        boxEntry(nodes_[static_cast<std::size_t>(right)].lo,
                 nodes_[static_cast<std::size_t>(right)].hi, origin, inverse, min_s, best);
    const bool left_first = enter_left <= enter_right;
    const double near_entry = left_first ? enter_left : enter_right;
    const double far_entry = left_first ? enter_right : enter_left;
    if (far_entry != std::numeric_limits<double>::infinity() && top < 63)
      stack[top++] = left_first ? right : left;
    if (near_entry != std::numeric_limits<double>::infinity() && top < 63)
      stack[top++] = left_first ? left : right;
  }
  if (best_triangle < 0) return false;
  const Triangle& t = triangles_[static_cast<std::size_t>(best_triangle)];
  s = best;
  normal = t.ab.cross(t.ac).normalized();
  return true;
}

namespace {

// PLY scalar types by name, and their sizes.
enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

bool plyType(const std::string& name, PlyType& type) {
  static const std::array<std::pair<const char*, PlyType>, 16> kNames = {{
      {"char", PlyType::kInt8},
      {"int8", PlyType::kInt8},
      {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},
      {"short", PlyType::kInt16},
      {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16},
      {"uint16", PlyType::kUint16},
      {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},
      {"uint", PlyType::kUint32},
      {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32},
      {"float32", PlyType::kFloat32},
      {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64},
  }};
  for (const auto& [n, t] : kNames)
    if (name == n) {
      type = t;
      return true;
    }
  return false;
}

struct PlyProperty {
  std::string name;
  bool list = false;
  PlyType count_type = PlyType::kUint8;  // lists only
  PlyType type = PlyType::kFloat32;      // the value, or the list's items
};

struct PlyElement {
  std::string name;
  std::size_t count = 0;
  std::vector<PlyProperty> properties;
};

// Reads one value of `type`: from text (ascii) or little-endian bytes.
class PlyReader {
 public:
  PlyReader(std::istream& in, bool ascii, std::string path)
      : in_(in), ascii_(ascii), path_(std::move(path)) {}

  double read(PlyType type) {
    if (ascii_) {
      double value = 0;
      if (!(in_ >> value)) fail("unexpected end of data or a non-number");
      return value;
    }
    auto bytes = [&](auto value) {
      char raw[sizeof(value)];
      if (!in_.read(raw, sizeof(value))) fail("unexpected end of data");
      // The host is little-endian (x86-64, aarch64), as the file.
      std::memcpy(&value, raw, sizeof(value));
      return static_cast<double>(value);
    };
    switch (type) {
      case PlyType::kInt8:
        return bytes(std::int8_t{});
      case PlyType::kUint8:
        return bytes(std::uint8_t{});
      case PlyType::kInt16:
        return bytes(std::int16_t{});
      case PlyType::kUint16:
        return bytes(std::uint16_t{});
      case PlyType::kInt32:
        return bytes(std::int32_t{});
      case PlyType::kUint32:
        return bytes(std::uint32_t{});
      case PlyType::kFloat32:
        return bytes(float{});
      case PlyType::kFloat64:
        return bytes(double{});
    }
    return 0;
  }

  [[noreturn]] void fail(const std::string& problem) const {
    throw std::runtime_error("PLY file '" + path_ + "': " + problem);
  }

 private:
  std::istream& in_;
  bool ascii_;
  std::string path_;
};

}  // namespace

}  // namespace sl::drivers::sim

namespace sl::drivers {

namespace {
// Larger than any mesh the simulator can ray-cast at a useful rate (a 1 GiB
// binary PLY holds ~45 M triangles).
constexpr std::uintmax_t kMaxPlyBytes = std::uintmax_t{1} << 30;
}  // namespace

using sim::PlyElement;
using sim::PlyProperty;
using sim::PlyReader;

SimMesh loadPlyMesh(const std::string& path, double scale) {
  auto fail = [&](const std::string& problem) -> void {
    throw std::runtime_error("PLY file '" + path + "': " + problem);
  };
  // Only regular files of bounded size: a device (/dev/zero) or a FIFO would
  // be read without end, a huge file into memory.
  std::error_code error;
  const auto status = std::filesystem::status(path, error);
  if (error || !std::filesystem::exists(status)) fail("cannot be opened (no such file)");
  if (std::filesystem::is_directory(status)) fail("is a directory, not a PLY file");
  if (!std::filesystem::is_regular_file(status)) fail("is not a regular file (a device or FIFO?)");
  const std::uintmax_t file_bytes = std::filesystem::file_size(path, error);
  if (error) fail("cannot be read: " + error.message());
  if (file_bytes > kMaxPlyBytes)
    fail("is " + std::to_string(file_bytes) + " bytes, more than the limit of " +
         std::to_string(kMaxPlyBytes));
  std::ifstream in(path, std::ios::binary);
  if (!in) fail("cannot be opened");
  std::string line;
  if (!std::getline(in, line) || line.substr(0, 3) != "ply") fail("does not start with 'ply'");
  bool ascii = false, have_format = false;
  std::vector<PlyElement> elements;
  while (true) {
    if (!std::getline(in, line)) fail("header has no end_header");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream words(line);
    std::string keyword;
    words >> keyword;
    if (keyword == "end_header") break;
    if (keyword == "comment" || keyword == "obj_info" || keyword.empty()) continue;
    if (keyword == "format") {
      std::string format;
      words >> format;
      if (format == "ascii")
        ascii = true;
      else if (format != "binary_little_endian")
        fail("format '" + format + "' is not supported (ascii or binary_little_endian)");
      have_format = true;
    } else if (keyword == "element") {
      PlyElement e;
      long long count = -1;
      words >> e.name >> count;
      if (count < 0) fail("bad element line '" + line + "'");
      // Every entry takes at least one byte (binary) or character (ascii):
      // a count beyond the file's size is a broken header, refused before
      // anything is allocated for it.
      if (static_cast<std::uintmax_t>(count) > file_bytes)
        fail("element '" + e.name + "' declares " + std::to_string(count) +
             " entries, more than the file's " + std::to_string(file_bytes) + " bytes can hold");
      e.count = static_cast<std::size_t>(count);
      elements.push_back(e);
    } else if (keyword == "property") {
      if (elements.empty()) fail("property before any element");
      PlyProperty p;
      std::string type;
      words >> type;
      if (type == "list") {
        std::string count_type, item_type;
        words >> count_type >> item_type >> p.name;
        p.list = true;
        if (!sim::plyType(count_type, p.count_type) || !sim::plyType(item_type, p.type))
          fail("unknown type in '" + line + "'");
      } else {
        words >> p.name;
        if (!sim::plyType(type, p.type)) fail("unknown type '" + type + "'");
      }
      elements.back().properties.push_back(p);
    } else {
      fail("unknown header line '" + line + "'");
    }
  }
  if (!have_format) fail("header has no format line");

  PlyReader reader(in, ascii, path);
  SimMesh mesh;
  bool have_vertices = false, have_faces = false;
  for (const PlyElement& e : elements) {
    int x = -1, y = -1, z = -1, indices = -1;
    for (std::size_t k = 0; k < e.properties.size(); ++k) {
      const std::string& name = e.properties[k].name;
      const int index = static_cast<int>(k);
      if (e.name == "vertex" && !e.properties[k].list) {
        if (name == "x") x = index;
        if (name == "y") y = index;
        if (name == "z") z = index;
      }
      if (e.name == "face" && e.properties[k].list &&
          (name == "vertex_indices" || name == "vertex_index"))
        indices = index;
    }
    if (e.name == "vertex") {
      if (x < 0 || y < 0 || z < 0) fail("vertex element lacks x, y or z");
      have_vertices = true;
      mesh.vertices.reserve(e.count);
    }
    if (e.name == "face") {
      if (indices < 0) fail("face element lacks vertex_indices");
      have_faces = true;
      mesh.triangles.reserve(e.count);
    }
    std::vector<double> values(e.properties.size());
    std::vector<std::int32_t> polygon;
    for (std::size_t i = 0; i < e.count; ++i) {
      for (std::size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        if (!p.list) {
          values[k] = reader.read(p.type);
          continue;
        }
        const double n = reader.read(p.count_type);
        if (n < 0 || n > 1e6) reader.fail("bad list length in element '" + e.name + "'");
        const bool keep = static_cast<int>(k) == indices;
        if (keep) polygon.clear();
        for (int j = 0; j < static_cast<int>(n); ++j) {
          const double v = reader.read(p.type);
          if (keep && !(v >= 0 && v < 2147483647.0))
            reader.fail("face " + std::to_string(i) + ": vertex index " + std::to_string(v) +
                        " out of range");
          if (keep) polygon.push_back(static_cast<std::int32_t>(v));
        }
      }
      if (e.name == "vertex") {
        mesh.vertices.emplace_back(static_cast<float>(values[static_cast<std::size_t>(x)] * scale),
                                   static_cast<float>(values[static_cast<std::size_t>(y)] * scale),
                                   static_cast<float>(values[static_cast<std::size_t>(z)] * scale));
      } else if (e.name == "face") {
        if (polygon.size() < 3) reader.fail("face " + std::to_string(i) + " has < 3 vertices");
        for (std::size_t j = 1; j + 1 < polygon.size(); ++j)
          mesh.triangles.push_back({polygon[0], polygon[j], polygon[j + 1]});
      }
    }
  }
  if (!have_vertices || !have_faces) fail("needs a vertex and a face element");
  for (const auto& t : mesh.triangles)
    for (std::int32_t v : t)
      if (v < 0 || static_cast<std::size_t>(v) >= mesh.vertices.size())
        fail("face index " + std::to_string(v) + " out of range (" +
             std::to_string(mesh.vertices.size()) + " vertices)");
  return mesh;
}

}  // namespace sl::drivers
