// Files of sl_register: scans as `slctl scan` / `slctl start --out` write
// them (binary PLY or PCD of tools/common/ply.h, with their stamp and unit in
// the header), robot pose files (TUM or CSV), the per-scan poses (TUM) and
// the merged cloud (binary PLY), and a voxel-averaging accumulator. Every
// error names the file (and line). Free functions and one plain class;
// thread-compatible.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <fstream>
#include <string>
#include <unordered_map>
#include <vector>

namespace sl::reg {

struct ScanFile {
  std::string path;
  std::int64_t stamp_ns = 0;            // from the header (0 if absent)
  bool has_stamp = false;
  std::vector<Eigen::Vector3f> points;  // mm (converted from the file's unit), finite only
};

// Reads a PLY (binary_little_endian or ascii; vertex x, y, z float or double,
// other vertex properties skipped) or a PCD (binary or ascii; fields x y z of
// type F). The unit comes from the header ("comment units m|mm" in PLY,
// "units m|mm" in PCD's first comment line); files without one are taken as
// `default_unit_m` says. Throws std::runtime_error naming the file.
ScanFile readScanFile(const std::string& path, bool default_unit_m = false);

// The *.ply and *.pcd files of a folder, sorted by name. Throws when the
// folder does not exist or holds none.
std::vector<std::string> listScanFiles(const std::string& dir);

struct StampedPose {
  std::int64_t stamp_ns = 0;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // mm
};

// Robot poses of the sensor (T_world_sensor). TUM (".tum", ".txt", anything
// else): "t tx ty tz qx qy qz qw" per line, t in seconds, '#' comments. CSV
// (".csv"): "stamp_ns,x,y,z,qx,qy,qz,qw", a header line allowed.
// Translations in metres unless unit_mm. Sorted by stamp on return; throws
// naming file and line on a malformed line, a non-unit quaternion or fewer
// than one pose.
std::vector<StampedPose> readPoses(const std::string& path, bool unit_mm = false);

// The pose at `stamp_ns`: interpolated between the bracketing poses (linear
// translation, slerp), or the nearest within tolerance_ns outside their
// range. Throws std::runtime_error naming `what` when there is none.
Eigen::Isometry3d poseAt(const std::vector<StampedPose>& poses, std::int64_t stamp_ns,
                         std::int64_t tolerance_ns, const std::string& what);

// TUM lines "t tx ty tz qx qy qz qw" (t in s, translation in m); written
// atomically.
void writeTum(const std::string& path, const std::vector<StampedPose>& poses);

// Streams points into a binary PLY (float x y z, and the scan index as
// intensity), the count patched into the header at close(). Units mm or m.
class PlyStreamWriter {
 public:
  PlyStreamWriter(const std::string& path, bool unit_m);
  void add(const Eigen::Vector3f& point_mm, float intensity);
  std::size_t close();  // renames the temporary file into place
  ~PlyStreamWriter();

 private:
  std::string path_, temporary_;
  std::ofstream out_;
  std::streampos count_at_;
  std::size_t count_ = 0;
  float scale_ = 1;
  bool closed_ = false;
};

// Voxel averaging of a point stream: one point per occupied voxel, the mean
// of its points (and of their intensities).
class VoxelAverager {
 public:
  explicit VoxelAverager(double voxel_mm);
  void add(const Eigen::Vector3f& point_mm, float intensity = 0);
  std::size_t size() const { return cells_.size(); }
  template <typename F>
  void forEach(F f) const {
    for (const auto& entry : cells_) f(mean(entry.second), intensity(entry.second));
  }

 private:
  struct Cell {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double intensity = 0;
    std::uint32_t count = 0;
  };
  static Eigen::Vector3f mean(const Cell& c) {
    return Eigen::Vector3f(float(c.sum.x() / c.count), float(c.sum.y() / c.count),
                           float(c.sum.z() / c.count));
  }
  static float intensity(const Cell& c) { return float(c.intensity / c.count); }
  double voxel_;
  std::unordered_map<std::uint64_t, Cell> cells_;
};

}  // namespace sl::reg
