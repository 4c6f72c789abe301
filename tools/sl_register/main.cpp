// sl_register [options] --out DIR PASS_DIR [PASS_DIR ...]: registers the
// scans of one or more passes (folders of PLY/PCD scans as `slctl scan` or
// `slctl start --out` write them, in name order along the motion) into one
// surface. Writes DIR/merged.ply, DIR/poses.tum and DIR/report.txt; progress
// on stderr. Exit codes: 0 ok, 1 error, 2 usage, 3 written but some scans
// were refused (named in the report and on stderr).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "registration.h"
#include "scan_files.h"

namespace {

struct Args {
  std::vector<std::string> passes;
  std::string out;
  std::string poses;
  bool poses_mm = false;
  bool default_unit_m = false;
  bool unit_m = false;
  std::vector<Eigen::Vector3d> velocities;  // mm/s, one per pass
  double merge_voxel_mm = 0;
  double tolerance_s = 0.1;
  sl::reg::RegisterOptions options;
};

int usage(const char* error = nullptr) {
  if (error) std::cerr << "sl_register: " << error << "\n";
  std::cerr <<
      "usage: sl_register [options] --out DIR PASS_DIR [PASS_DIR ...]\n"
      "  PASS_DIR            scans of one pass (*.ply, *.pcd), in name order along the motion\n"
      "  --out DIR           writes merged.ply, poses.tum (T_world_scan), report.txt\n"
      "  --units mm|m        unit of merged.ply (default mm)\n"
      "  --poses FILE        prior: robot poses of the sensor (scan frame) in a world frame;\n"
      "                      TUM (t[s] x y z qx qy qz qw) or .csv (stamp_ns,x,y,z,qx,qy,qz,qw),\n"
      "                      matched to the scans' stamps; needed for several passes\n"
      "  --poses-units mm|m  translation unit of --poses (default m)\n"
      "  --pose-tolerance S  nearest pose allowed this far outside the file's range (default 0.1)\n"
      "  --velocity X,Y,Z    prior without --poses: the pass's velocity (mm/s) in its first\n"
      "                      scan's frame; once per PASS_DIR, in order\n"
      "  --pairwise          pairwise ICP chain only (default: multi-way pose graph)\n"
      "  --voxel MM          registration voxel (default 2)\n"
      "  --merge-voxel MM    voxel-average merged.ply (default 0: every point)\n"
      "  --min-overlap F     (default 0.2)  --min-fitness F (default 0.3)\n"
      "  --max-rmse MM       point-to-plane RMSE limit of an edge (default 0.5)\n"
      "  --max-correction MM ICP's largest change of the prior guess (default 25)\n"
      "  --input-units mm|m  unit of scans without a 'units' header comment (default mm)\n";
  return 2;
}

bool parseUnit(const std::string& v, bool* metre) {
  if (v == "m") return *metre = true, true;
  if (v == "mm") return *metre = false, true;
  return false;
}

bool parseNumber(const std::string& v, double* out) {
  try {
    std::size_t used = 0;
    *out = std::stod(v, &used);
    return used == v.size();
  } catch (const std::exception&) {
    return false;
  }
}

std::optional<Args> parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::optional<std::string> {
      if (i + 1 >= argc) return std::nullopt;
      return std::string(argv[++i]);
    };
    auto number = [&](double* out) {
      const auto v = value();
      return v && parseNumber(*v, out);
    };
    bool ok = true;
    if (arg == "--out") {
      const auto v = value();
      ok = bool(v);
      if (v) a.out = *v;
    } else if (arg == "--poses") {
      const auto v = value();
      ok = bool(v);
      if (v) a.poses = *v;
    } else if (arg == "--units") {
      const auto v = value();
      ok = v && parseUnit(*v, &a.unit_m);
    } else if (arg == "--input-units") {
      const auto v = value();
      ok = v && parseUnit(*v, &a.default_unit_m);
    } else if (arg == "--poses-units") {
      const auto v = value();
      bool metre = true;
      ok = v && parseUnit(*v, &metre);
      a.poses_mm = !metre;
    } else if (arg == "--velocity") {
      const auto v = value();
      Eigen::Vector3d vel;
      char c1 = 0, c2 = 0;
      std::istringstream in(v ? *v : "");
      ok = v && (in >> vel.x() >> c1 >> vel.y() >> c2 >> vel.z()) && c1 == ',' && c2 == ',';
      a.velocities.push_back(vel);
    } else if (arg == "--pairwise") {
      a.options.multiway = false;
    } else if (arg == "--voxel") {
      ok = number(&a.options.voxel_mm) && a.options.voxel_mm > 0;
    } else if (arg == "--merge-voxel") {
      ok = number(&a.merge_voxel_mm) && a.merge_voxel_mm >= 0;
    } else if (arg == "--min-overlap") {
      ok = number(&a.options.min_overlap);
    } else if (arg == "--min-fitness") {
      ok = number(&a.options.min_fitness);
    } else if (arg == "--max-rmse") {
      ok = number(&a.options.max_rmse_mm);
    } else if (arg == "--max-correction") {
      ok = number(&a.options.max_correction_mm);
    } else if (arg == "--pose-tolerance") {
      ok = number(&a.tolerance_s) && a.tolerance_s >= 0;
    } else if (arg == "-h" || arg == "--help") {
      usage();
      std::exit(0);
    } else if (!arg.empty() && arg[0] == '-') {
      usage(("unknown option " + arg).c_str());
      std::exit(2);
    } else {
      a.passes.push_back(arg);
    }
    if (!ok) {
      usage(("bad or missing value for " + arg).c_str());
      std::exit(2);
    }
  }
  return a;
}

}  // namespace

int main(int argc, char** argv) {
  const std::optional<Args> parsed = parse(argc, argv);
  if (!parsed) return usage();
  const Args& args = *parsed;
  if (args.out.empty()) return usage("--out DIR is required");
  if (args.passes.empty()) return usage("no PASS_DIR given");
  if (!args.velocities.empty() && args.velocities.size() != args.passes.size())
    return usage("--velocity must be given once per PASS_DIR");
  if (!args.poses.empty() && !args.velocities.empty())
    return usage("--poses and --velocity exclude each other");
  if (args.passes.size() > 1 && args.poses.empty())
    return usage("several passes need --poses (their placement relative to each other)");
  try {
    auto say = [](const std::string& line) { std::cerr << "sl_register: " << line << "\n"; };
    std::vector<sl::reg::StampedPose> robot;
    if (!args.poses.empty()) robot = sl::reg::readPoses(args.poses, args.poses_mm);
    // Scans, thinned to a quarter of the registration voxel (the library
    // downsamples further), so memory stays bounded for long passes.
    std::vector<sl::reg::ScanInput> scans;
    std::vector<std::string> files;
    for (std::size_t p = 0; p < args.passes.size(); ++p) {
      std::int64_t first_stamp = 0;
      for (const std::string& file : sl::reg::listScanFiles(args.passes[p])) {
        sl::reg::ScanFile f = sl::reg::readScanFile(file, args.default_unit_m);
        sl::reg::ScanInput s;
        s.name = std::filesystem::path(file).filename().string();
        if (args.passes.size() > 1) s.name = std::to_string(p) + "/" + s.name;
        s.pass = int(p);
        s.stamp_ns = f.stamp_ns;
        const bool first = scans.empty() || scans.back().pass != int(p);
        if (first) first_stamp = f.stamp_ns;
        if ((!robot.empty() || !args.velocities.empty()) && !f.has_stamp)
          throw std::runtime_error(file + ": no stamp_ns in the header, needed for the prior");
        if (!robot.empty()) {
          s.initial = sl::reg::poseAt(robot, f.stamp_ns, std::int64_t(args.tolerance_s * 1e9), file);
        } else if (!args.velocities.empty()) {
          s.initial = Eigen::Isometry3d::Identity();
          s.initial.translation() = args.velocities[p] * (double(f.stamp_ns - first_stamp) * 1e-9);
        }
        sl::reg::VoxelAverager thin(args.options.voxel_mm / 4);
        for (const Eigen::Vector3f& point : f.points) thin.add(point);
        s.points.reserve(thin.size());
        thin.forEach([&](const Eigen::Vector3f& point, float) { s.points.push_back(point); });
        say("read " + file + ": " + std::to_string(f.points.size()) + " points");
        scans.push_back(std::move(s));
        files.push_back(file);
      }
    }
    const auto start = std::chrono::steady_clock::now();
    const sl::reg::RegisterResult result = sl::reg::registerScans(scans, args.options, say);
    say("registered in " +
        std::to_string(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()) +
        " s");
    std::filesystem::create_directories(args.out);
    // Poses (T_world_scan) of the registered scans.
    std::vector<sl::reg::StampedPose> poses;
    for (std::size_t i = 0; i < scans.size(); ++i)
      if (result.registered[i]) poses.push_back({scans[i].stamp_ns, result.poses[i]});
    sl::reg::writeTum(args.out + "/poses.tum", poses);
    {
      std::ofstream report(args.out + "/report.txt");
      report << sl::reg::formatReport(scans, result);
      for (std::size_t i = 0; i < scans.size(); ++i)
        report << "scan " << scans[i].name << " " << (result.registered[i] ? "registered" : "refused")
               << "\n";
      if (!report.flush()) throw std::runtime_error(args.out + "/report.txt: write failed");
    }
    // Merged cloud: every registered scan's points, re-read at full density.
    sl::reg::PlyStreamWriter writer(args.out + "/merged.ply", args.unit_m);
    std::optional<sl::reg::VoxelAverager> averaged;
    if (args.merge_voxel_mm > 0) averaged.emplace(args.merge_voxel_mm);
    for (std::size_t i = 0; i < scans.size(); ++i) {
      if (!result.registered[i]) continue;
      const sl::reg::ScanFile f = sl::reg::readScanFile(files[i], args.default_unit_m);
      const Eigen::Isometry3f T = result.poses[i].cast<float>();
      for (const Eigen::Vector3f& p : f.points) {
        if (averaged) averaged->add(T * p, float(i));
        else writer.add(T * p, float(i));
      }
    }
    if (averaged) averaged->forEach([&](const Eigen::Vector3f& p, float s) { writer.add(p, s); });
    const std::size_t written = writer.close();
    say("wrote " + args.out + "/merged.ply (" + std::to_string(written) + " points), poses.tum, report.txt");
    for (const std::string& r : result.refused) say("refused " + r);
    return result.refused.empty() ? 0 : 3;
  } catch (const std::invalid_argument& e) {
    std::cerr << "sl_register: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "sl_register: " << e.what() << "\n";
    return 1;
  }
}
