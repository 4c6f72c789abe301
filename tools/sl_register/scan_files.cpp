#include "scan_files.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace sl::reg {

namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw std::runtime_error(path + ": " + what);
}

// A file's length, for size checks before allocating.
std::uintmax_t fileSize(const std::string& path) {
  std::error_code error;
  const std::uintmax_t size = std::filesystem::file_size(path, error);
  if (error) fail(path, "cannot read its size: " + error.message());
  return size;
}

struct Property {
  std::string name;
  std::string type;  // PLY type name
  int size = 0;
};

int plySize(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" ||
      type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  return 0;
}

double readBinary(const char* p, const Property& prop) {
  if (prop.type == "float" || prop.type == "float32") {
    float v;
    std::memcpy(&v, p, 4);
    return v;
  }
  if (prop.type == "double" || prop.type == "float64") {
    double v;
    std::memcpy(&v, p, 8);
    return v;
  }
  return std::numeric_limits<double>::quiet_NaN();
}

ScanFile readPly(const std::string& path, bool default_unit_m) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open");
  std::string line;
  if (!std::getline(in, line) || line != "ply") fail(path, "not a PLY file (no 'ply' line)");
  ScanFile scan;
  scan.path = path;
  bool unit_m = default_unit_m, binary = false, in_vertex = false;
  std::uint64_t vertices = 0;
  bool vertex_seen = false;
  std::vector<Property> props;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key == "end_header") break;
    if (key == "format") {
      std::string f;
      words >> f;
      if (f == "binary_little_endian") binary = true;
      else if (f == "ascii") binary = false;
      else fail(path, "line " + std::to_string(line_no) + ": format '" + f + "' not supported");
    } else if (key == "comment") {
      std::string what, value;
      words >> what >> value;
      if (what == "units") {
        if (value == "m") unit_m = true;
        else if (value == "mm") unit_m = false;
        else fail(path, "line " + std::to_string(line_no) + ": unknown unit '" + value + "'");
      } else if (what == "stamp_ns") {
        try {
          scan.stamp_ns = std::stoll(value);
          scan.has_stamp = true;
        } catch (const std::exception&) {
          fail(path, "line " + std::to_string(line_no) + ": bad stamp_ns '" + value + "'");
        }
      }
    } else if (key == "element") {
      std::string name;
      std::uint64_t count = 0;
      words >> name >> count;
      in_vertex = name == "vertex";
      if (in_vertex) vertices = count, vertex_seen = true;
      else if (!vertex_seen) fail(path, "elements before 'vertex' are not supported");
    } else if (key == "property" && in_vertex) {
      Property p;
      words >> p.type;
      if (p.type == "list") fail(path, "list properties in 'vertex' are not supported");
      words >> p.name;
      p.size = plySize(p.type);
      if (p.size == 0) fail(path, "line " + std::to_string(line_no) + ": unknown type '" + p.type + "'");
      props.push_back(p);
    }
  }
  if (!in) fail(path, "header has no end_header");
  int ix = -1, iy = -1, iz = -1;
  std::size_t offset[3] = {0, 0, 0}, stride = 0;
  for (std::size_t k = 0; k < props.size(); ++k) {
    if (props[k].name == "x") ix = int(k), offset[0] = stride;
    if (props[k].name == "y") iy = int(k), offset[1] = stride;
    if (props[k].name == "z") iz = int(k), offset[2] = stride;
    stride += std::size_t(props[k].size);
  }
  if (ix < 0 || iy < 0 || iz < 0) fail(path, "vertex has no x, y, z properties");
  const float scale = unit_m ? 1000.0f : 1.0f;
  if (binary) {
    const std::uintmax_t need = vertices * stride;
    const std::uintmax_t have = fileSize(path) - std::uintmax_t(in.tellg());
    if (need > have)
      fail(path, std::to_string(vertices) + " vertices need " + std::to_string(need) +
                     " bytes, the file has " + std::to_string(have));
    std::vector<char> data(need);
    in.read(data.data(), std::streamsize(need));
    scan.points.reserve(vertices);
    for (std::uint64_t v = 0; v < vertices; ++v) {
      const char* base = data.data() + v * stride;
      const Eigen::Vector3f p(float(readBinary(base + offset[0], props[std::size_t(ix)])),
                              float(readBinary(base + offset[1], props[std::size_t(iy)])),
                              float(readBinary(base + offset[2], props[std::size_t(iz)])));
      if (p.allFinite()) scan.points.push_back(p * scale);
    }
  } else {
    for (std::uint64_t v = 0; v < vertices; ++v) {
      if (!std::getline(in, line)) fail(path, "ends after " + std::to_string(v) + " of " +
                                                  std::to_string(vertices) + " vertices");
      std::istringstream words(line);
      std::vector<double> values(props.size());
      for (double& value : values)
        if (!(words >> value)) fail(path, "vertex " + std::to_string(v) + ": too few values");
      const Eigen::Vector3f p(float(values[std::size_t(ix)]), float(values[std::size_t(iy)]),
                              float(values[std::size_t(iz)]));
      if (p.allFinite()) scan.points.push_back(p * scale);
    }
  }
  return scan;
}

ScanFile readPcd(const std::string& path, bool default_unit_m) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open");
  ScanFile scan;
  scan.path = path;
  bool unit_m = default_unit_m;
  std::vector<std::string> fields;
  std::vector<int> sizes, counts;
  std::vector<char> types;
  std::uint64_t points = 0;
  std::string data, line;
  int line_no = 0;
  while (data.empty() && std::getline(in, line)) {
    ++line_no;
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (!key.empty() && key[0] == '#') {
      // tools/common/ply.h: "# .PCD v0.7 - sl-sensor, units mm, frame F, stamp_ns N"
      const auto units = line.find("units ");
      if (units != std::string::npos) unit_m = line.compare(units + 6, 2, "m,") == 0;
      const auto stamp = line.find("stamp_ns ");
      if (stamp != std::string::npos) {
        try {
          scan.stamp_ns = std::stoll(line.substr(stamp + 9));
          scan.has_stamp = true;
        } catch (const std::exception&) {
          fail(path, "line " + std::to_string(line_no) + ": bad stamp_ns");
        }
      }
    } else if (key == "FIELDS") {
      for (std::string f; words >> f;) fields.push_back(f);
    } else if (key == "SIZE") {
      for (int s; words >> s;) sizes.push_back(s);
    } else if (key == "TYPE") {
      for (char t; words >> t;) types.push_back(t);
    } else if (key == "COUNT") {
      for (int c; words >> c;) counts.push_back(c);
    } else if (key == "POINTS") {
      words >> points;
    } else if (key == "DATA") {
      words >> data;
    }
  }
  if (data != "binary" && data != "ascii") fail(path, "DATA '" + data + "' not supported (binary or ascii)");
  if (counts.empty()) counts.assign(fields.size(), 1);
  if (sizes.size() != fields.size() || types.size() != fields.size() || counts.size() != fields.size())
    fail(path, "FIELDS, SIZE, TYPE and COUNT differ in length");
  int ix = -1, iy = -1, iz = -1;
  std::vector<std::size_t> offsets;
  std::size_t stride = 0;
  for (std::size_t k = 0; k < fields.size(); ++k) {
    offsets.push_back(stride);
    if (fields[k] == "x") ix = int(k);
    if (fields[k] == "y") iy = int(k);
    if (fields[k] == "z") iz = int(k);
    stride += std::size_t(sizes[k] * counts[k]);
  }
  if (ix < 0 || iy < 0 || iz < 0) fail(path, "no x, y, z fields");
  for (int k : {ix, iy, iz})
    if (types[std::size_t(k)] != 'F' || sizes[std::size_t(k)] != 4)
      fail(path, "x, y, z must be float (TYPE F, SIZE 4)");
  const float scale = unit_m ? 1000.0f : 1.0f;
  scan.points.reserve(points);
  if (data == "binary") {
    const std::uintmax_t need = points * stride;
    const std::uintmax_t have = fileSize(path) - std::uintmax_t(in.tellg());
    if (need > have)
      fail(path, std::to_string(points) + " points need " + std::to_string(need) +
                     " bytes, the file has " + std::to_string(have));
    std::vector<char> buffer(need);
    in.read(buffer.data(), std::streamsize(need));
    for (std::uint64_t v = 0; v < points; ++v) {
      float xyz[3];
      const int idx[3] = {ix, iy, iz};
      for (int a = 0; a < 3; ++a)
        std::memcpy(&xyz[a], buffer.data() + v * stride + offsets[std::size_t(idx[a])], 4);
      const Eigen::Vector3f p(xyz[0], xyz[1], xyz[2]);
      if (p.allFinite()) scan.points.push_back(p * scale);
    }
  } else {
    for (std::uint64_t v = 0; v < points; ++v) {
      if (!std::getline(in, line)) fail(path, "ends after " + std::to_string(v) + " points");
      std::istringstream words(line);
      std::vector<double> values;
      for (std::string w; words >> w;) values.push_back(w == "nan" ? std::nan("") : std::stod(w));
      if (values.size() < fields.size()) fail(path, "point " + std::to_string(v) + ": too few values");
      const Eigen::Vector3f p(float(values[std::size_t(ix)]), float(values[std::size_t(iy)]),
                              float(values[std::size_t(iz)]));
      if (p.allFinite()) scan.points.push_back(p * scale);
    }
  }
  return scan;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

}  // namespace

ScanFile readScanFile(const std::string& path, bool default_unit_m) {
  const std::string ext = lower(std::filesystem::path(path).extension().string());
  if (ext == ".ply") return readPly(path, default_unit_m);
  if (ext == ".pcd") return readPcd(path, default_unit_m);
  fail(path, "not a .ply or .pcd file");
}

std::vector<std::string> listScanFiles(const std::string& dir) {
  std::error_code error;
  if (!std::filesystem::is_directory(dir, error)) fail(dir, "not a folder");
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string ext = lower(entry.path().extension().string());
    if (entry.is_regular_file() && (ext == ".ply" || ext == ".pcd"))
      files.push_back(entry.path().string());
  }
  if (files.empty()) fail(dir, "holds no .ply or .pcd scans");
  std::sort(files.begin(), files.end());
  return files;
}

std::vector<StampedPose> readPoses(const std::string& path, bool unit_mm) {
  std::ifstream in(path);
  if (!in) fail(path, "cannot open");
  const bool csv = lower(std::filesystem::path(path).extension().string()) == ".csv";
  std::vector<StampedPose> poses;
  std::string line;
  int line_no = 0;
  const double scale = unit_mm ? 1.0 : 1000.0;
  while (std::getline(in, line)) {
    ++line_no;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    if (csv) std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream words(line);
    std::string stamp_text;
    double v[7];
    words >> stamp_text;
    bool ok = true;
    for (double& x : v) ok = ok && bool(words >> x);
    const std::string where = "line " + std::to_string(line_no);
    if (!ok) {
      if (csv && poses.empty() && line_no == 1) continue;  // a header
      fail(path, where + ": expected 8 numbers (stamp x y z qx qy qz qw)");
    }
    StampedPose p;
    try {
      std::size_t used = 0;
      if (csv) {
        p.stamp_ns = std::stoll(stamp_text, &used);
      } else {
        // Seconds with up to 9 decimals, kept exact in integer ns.
        const auto dot = stamp_text.find('.');
        const std::string whole = stamp_text.substr(0, dot);
        std::string frac = dot == std::string::npos ? "" : stamp_text.substr(dot + 1);
        if (frac.size() > 9) frac.resize(9);
        frac.append(9 - frac.size(), '0');
        p.stamp_ns = std::stoll(whole, &used) * 1'000'000'000 + std::stoll(frac);
        used = stamp_text.size();
      }
      if (used != stamp_text.size()) throw std::invalid_argument("trailing");
    } catch (const std::exception&) {
      fail(path, where + ": bad stamp '" + stamp_text + "'");
    }
    const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
    if (std::abs(q.norm() - 1) > 1e-3) fail(path, where + ": quaternion is not unit");
    p.pose = Eigen::Isometry3d::Identity();
    p.pose.linear() = q.normalized().toRotationMatrix();
    p.pose.translation() = Eigen::Vector3d(v[0], v[1], v[2]) * scale;
    poses.push_back(p);
  }
  if (poses.empty()) fail(path, "holds no poses");
  std::stable_sort(poses.begin(), poses.end(),
                   [](const StampedPose& a, const StampedPose& b) { return a.stamp_ns < b.stamp_ns; });
  return poses;
}

Eigen::Isometry3d poseAt(const std::vector<StampedPose>& poses, std::int64_t stamp_ns,
                         std::int64_t tolerance_ns, const std::string& what) {
  auto after = std::lower_bound(poses.begin(), poses.end(), stamp_ns,
                                [](const StampedPose& p, std::int64_t t) { return p.stamp_ns < t; });
  if (after != poses.end() && after->stamp_ns == stamp_ns) return after->pose;
  if (after != poses.begin() && after != poses.end()) {
    const StampedPose& a = *(after - 1);
    const StampedPose& b = *after;
    const double f = double(stamp_ns - a.stamp_ns) / double(b.stamp_ns - a.stamp_ns);
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.linear() = Eigen::Quaterniond(a.pose.linear())
                     .slerp(f, Eigen::Quaterniond(b.pose.linear()))
                     .toRotationMatrix();
    p.translation() = (1 - f) * a.pose.translation() + f * b.pose.translation();
    return p;
  }
  const StampedPose& nearest = after == poses.end() ? poses.back() : poses.front();
  if (std::llabs(nearest.stamp_ns - stamp_ns) <= tolerance_ns) return nearest.pose;
  throw std::runtime_error(what + ": no robot pose within " + std::to_string(tolerance_ns * 1e-9) +
                           " s of its stamp " + std::to_string(stamp_ns) + " ns");
}

void writeTum(const std::string& path, const std::vector<StampedPose>& poses) {
  const std::string temporary = path + ".part";
  {
    std::ofstream out(temporary);
    if (!out) fail(temporary, "cannot open for writing");
    out << "# timestamp tx ty tz qx qy qz qw (s, m; T_world_scan, sl_register)\n";
    out << std::fixed;
    for (const StampedPose& p : poses) {
      const Eigen::Quaterniond q(p.pose.linear());
      const Eigen::Vector3d t = p.pose.translation() / 1000.0;
      out << p.stamp_ns / 1'000'000'000 << '.' << std::setw(9) << std::setfill('0')
          << p.stamp_ns % 1'000'000'000 << std::setfill(' ') << std::setprecision(7) << ' '
          << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << std::setprecision(9) << q.x() << ' '
          << q.y() << ' ' << q.z() << ' ' << q.w() << '\n';
    }
    if (!out.flush()) fail(temporary, "write failed (disk full?)");
  }
  std::filesystem::rename(temporary, path);
}

PlyStreamWriter::PlyStreamWriter(const std::string& path, bool unit_m)
    : path_(path), temporary_(path + ".part"), scale_(unit_m ? 1e-3f : 1.0f) {
  out_.open(temporary_, std::ios::binary | std::ios::trunc);
  if (!out_) fail(temporary_, "cannot open for writing");
  out_ << "ply\nformat binary_little_endian 1.0\ncomment generator sl_register\n"
       << "comment units " << (unit_m ? "m" : "mm") << "\n"
       << "comment intensity = index of the scan the point comes from\nelement vertex ";
  count_at_ = out_.tellp();
  out_ << "0000000000000000\n"
       << "property float x\nproperty float y\nproperty float z\nproperty float intensity\n"
       << "end_header\n";
}

void PlyStreamWriter::add(const Eigen::Vector3f& point_mm, float intensity) {
  const float v[4] = {point_mm.x() * scale_, point_mm.y() * scale_, point_mm.z() * scale_, intensity};
  out_.write(reinterpret_cast<const char*>(v), sizeof v);
  ++count_;
}

std::size_t PlyStreamWriter::close() {
  char digits[17];
  std::snprintf(digits, sizeof digits, "%-16zu", count_);
  out_.seekp(count_at_);
  out_.write(digits, 16);
  if (!out_.flush()) fail(temporary_, "write failed (disk full?)");
  out_.close();
  std::filesystem::rename(temporary_, path_);
  closed_ = true;
  return count_;
}

PlyStreamWriter::~PlyStreamWriter() {
  if (!closed_) {
    out_.close();
    std::error_code ignored;
    std::filesystem::remove(temporary_, ignored);
  }
}

VoxelAverager::VoxelAverager(double voxel_mm) : voxel_(voxel_mm) {
  if (!(voxel_mm > 0)) throw std::invalid_argument("VoxelAverager: voxel size must be > 0");
}

void VoxelAverager::add(const Eigen::Vector3f& point_mm, float intensity) {
  // 21 bits per axis, offset: voxels of +-2^20 cells around the origin.
  auto cell = [&](float v) {
    return std::uint64_t(std::int64_t(std::floor(double(v) / voxel_)) + (1 << 20)) & 0x1FFFFF;
  };
  const std::uint64_t key = cell(point_mm.x()) | cell(point_mm.y()) << 21 | cell(point_mm.z()) << 42;
  Cell& c = cells_[key];
  c.sum += point_mm.cast<double>();
  c.intensity += intensity;
  ++c.count;
}

}  // namespace sl::reg
