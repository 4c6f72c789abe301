// sl_register's library: a synthetic pass over a relief with known poses is
// recovered from a perturbed prior; scans that overlap nothing, or whose
// content matches nothing, are refused and named; the scan and pose files
// round-trip.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <random>


#include "registration.h"
#include "scan_files.h"
#include "common/ply.h"

namespace {

constexpr double kPi = 3.14159265358979323846;

// A plaster-like relief: bumps and ridges of a few mm on a wall at z = 400 mm.
struct Bump {
  double x, y, height, sigma;
};
const std::vector<Bump>& bumps() {
  static const std::vector<Bump> b = [] {
    std::vector<Bump> out;
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(0, 1);
    for (int k = 0; k < 60; ++k)
      out.push_back({-200 + 800 * u(rng), -150 + 300 * u(rng), (u(rng) - 0.5) * 6, 8 + 20 * u(rng)});
    return out;
  }();
  return b;
}
double relief(double x, double y) {
  double z = 400;
  for (const Bump& b : bumps()) {
    const double d2 = (x - b.x) * (x - b.x) + (y - b.y) * (y - b.y);
    if (d2 < 25 * b.sigma * b.sigma) z += b.height * std::exp(-d2 / (2 * b.sigma * b.sigma));
  }
  return z + 0.8 * std::sin(0.11 * x + 0.05 * y) + 0.5 * std::sin(0.07 * y - 0.13 * x);
}

Eigen::Isometry3d poseOf(double tx, double ty, double rz_deg) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  p.linear() = Eigen::AngleAxisd(rz_deg * kPi / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  p.translation() = Eigen::Vector3d(tx, ty, 0);
  return p;
}

// The relief seen from `truth` (T_world_scan): a 160 x 120 mm window on a
// 1.5 mm grid, in the scan frame, with 0.03 mm noise.
std::vector<Eigen::Vector3f> view(const Eigen::Isometry3d& truth, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 0.03);
  std::vector<Eigen::Vector3f> points;
  const Eigen::Vector3d c = truth.translation();
  for (double y = c.y() - 60; y <= c.y() + 60; y += 1.5)
    for (double x = c.x() - 80; x <= c.x() + 80; x += 1.5) {
      const Eigen::Vector3d w(x, y, relief(x, y) + noise(rng));
      points.push_back((truth.inverse() * w).cast<float>());
    }
  return points;
}

double translationError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.inverse() * b).translation().norm();
}
double angleErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd((a.inverse() * b).linear()).angle() * 180 / kPi;
}

struct Pass {
  std::vector<sl::reg::ScanInput> scans;
  std::vector<Eigen::Isometry3d> truth;
};

// 12 scans 15 mm apart along x with small rotations; the prior is the truth
// with a growing error (2 mm and 0.2 deg per scan, as a sliding odometry).
Pass makePass() {
  Pass pass;
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0, 1);
  for (int k = 0; k < 12; ++k) {
    const Eigen::Isometry3d truth = poseOf(15.0 * k, 2 * std::sin(0.5 * k), 0.3 * std::sin(0.7 * k));
    sl::reg::ScanInput s;
    s.name = "scan_" + std::to_string(k);
    s.stamp_ns = 1'000'000'000LL * k;
    s.points = view(truth, 100 + k);
    s.initial = k == 0 ? truth : truth * poseOf(1.5 * g(rng), 1.5 * g(rng), 0.2 * g(rng));
    pass.scans.push_back(std::move(s));
    pass.truth.push_back(truth);
  }
  return pass;
}

}  // namespace

TEST_CASE("a synthetic pass with known poses is recovered, multi-way at least as well as pairwise") {
  const Pass pass = makePass();
  sl::reg::RegisterOptions options;
  options.multiway = false;
  const sl::reg::RegisterResult pairwise = sl::reg::registerScans(pass.scans, options);
  options.multiway = true;
  const sl::reg::RegisterResult multiway = sl::reg::registerScans(pass.scans, options);
  INFO(sl::reg::formatReport(pass.scans, multiway));
  CHECK(pairwise.refused.empty());
  CHECK(multiway.refused.empty());
  double worst_pairwise = 0, worst_multiway = 0, worst_deg = 0;
  for (std::size_t k = 0; k < pass.truth.size(); ++k) {
    worst_pairwise = std::max(worst_pairwise, translationError(pass.truth[k], pairwise.poses[k]));
    worst_multiway = std::max(worst_multiway, translationError(pass.truth[k], multiway.poses[k]));
    worst_deg = std::max(worst_deg, angleErrorDeg(pass.truth[k], multiway.poses[k]));
  }
  INFO("worst pose error: pairwise " << worst_pairwise << " mm, multi-way " << worst_multiway
                                     << " mm, " << worst_deg << " deg");
  // The prior is off by 1.5 mm (sigma per axis) and 0.2 deg; the registration is within
  // 0.15 mm (pairwise), 0.1 mm and 0.05 deg (multi-way) of the truth for every scan.
  CHECK(worst_pairwise < 0.15);
  CHECK(worst_multiway < 0.1);
  CHECK(worst_deg < 0.05);
  CHECK(worst_multiway <= worst_pairwise + 1e-3);
  // The multi-way result carries the pairwise chain it started from: the
  // pairwise run's poses and edges (one run gives both, as sl_eval wall uses).
  CHECK(pairwise.pairwise == nullptr);
  REQUIRE(multiway.pairwise != nullptr);
  CHECK_FALSE(multiway.pairwise->multiway);
  REQUIRE(multiway.pairwise->poses.size() == pairwise.poses.size());
  for (std::size_t k = 0; k < pairwise.poses.size(); ++k)
    CHECK(multiway.pairwise->poses[k].isApprox(pairwise.poses[k], 1e-12));
  CHECK(multiway.pairwise->edges.size() == pairwise.edges.size());
  CHECK(multiway.pairwise->registered == pairwise.registered);
  // Skip edges were measured and used.
  int skips = 0;
  for (const auto& e : multiway.edges) skips += e.kind == sl::reg::EdgeKind::kSkip && e.accepted;
  CHECK(skips >= 10);
}

TEST_CASE("a scan that overlaps nothing, or matches nothing, is refused and named") {
  Pass pass = makePass();
  pass.scans.resize(6);
  pass.truth.resize(6);
  // Scan 3: placed by its prior 1 m away from everything.
  pass.scans[3].initial = poseOf(1000, 800, 0);
  // Scan 4: where the pass is, but of another surface (a tilted plane).
  for (Eigen::Vector3f& p : pass.scans[4].points) p.z() = 400 + 0.3f * p.x();
  for (bool multiway : {false, true}) {
    sl::reg::RegisterOptions options;
    options.multiway = multiway;
    const sl::reg::RegisterResult r = sl::reg::registerScans(pass.scans, options);
    const std::string report = sl::reg::formatReport(pass.scans, r);
    INFO(report);
    REQUIRE(r.refused.size() == 2);
    CHECK(r.refused[0].rfind("scan_3:", 0) == 0);
    CHECK(r.refused[1].rfind("scan_4:", 0) == 0);
    CHECK_FALSE(r.registered[3]);
    CHECK_FALSE(r.registered[4]);
    CHECK(report.find("refused scan_3") != std::string::npos);
    CHECK(report.find("too little overlap") != std::string::npos);
    CHECK(report.find("poor fit") != std::string::npos);
    // The others are still registered, across the gap (2 -> 5 by a skip edge).
    for (int k : {0, 1, 2, 5}) {
      CHECK(r.registered[std::size_t(k)]);
      CHECK(translationError(pass.truth[std::size_t(k)], r.poses[std::size_t(k)]) < 0.15);
    }
  }
}

TEST_CASE("too few points is an error naming the scan") {
  Pass pass = makePass();
  pass.scans[2].points.resize(10);
  CHECK_THROWS_WITH(sl::reg::registerScans(pass.scans, {}), Catch::Contains("scan 'scan_2'"));
}

TEST_CASE("scan files as slctl writes them, and pose files, round-trip") {
  const auto dir = std::filesystem::temp_directory_path() / "sl_register_test";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  sl::pipeline::PointCloud cloud;
  cloud.width = 3;
  cloud.height = 1;
  cloud.stamp_ns = 1234567890123456789LL;
  cloud.frame_id = "f";
  const float nan = std::nanf("");
  cloud.points = {{1, 2, 300, 5}, {nan, nan, nan, 0}, {-4, 5.5f, 401, 7}};
  for (auto unit : {sl::tools::LengthUnit::kMetre, sl::tools::LengthUnit::kMillimetre}) {
    for (const char* ext : {".ply", ".pcd"}) {
      const std::string path = (dir / (std::string("s") + ext)).string();
      if (std::string(ext) == ".ply") sl::tools::writePly(cloud, path, unit);
      else sl::tools::writePcd(cloud, path, unit);
      const sl::reg::ScanFile f = sl::reg::readScanFile(path);
      CHECK(f.has_stamp);
      CHECK(f.stamp_ns == cloud.stamp_ns);
      REQUIRE(f.points.size() == 2);
      CHECK(f.points[1].x() == Approx(-4).margin(1e-4));
      CHECK(f.points[1].z() == Approx(401).margin(1e-3));
    }
  }
  CHECK(sl::reg::listScanFiles(dir.string()).size() == 2);
  CHECK_THROWS_WITH(sl::reg::listScanFiles((dir / "none").string()), Catch::Contains("not a folder"));

  std::vector<sl::reg::StampedPose> poses = {{1'500'000'000, poseOf(10, 20, 5)},
                                             {2'500'000'000, poseOf(30, 20, 15)}};
  const std::string tum = (dir / "p.tum").string();
  sl::reg::writeTum(tum, poses);
  const auto back = sl::reg::readPoses(tum);
  REQUIRE(back.size() == 2);
  CHECK(back[1].stamp_ns == 2'500'000'000);
  CHECK(translationError(back[1].pose, poses[1].pose) < 1e-3);
  const Eigen::Isometry3d mid = sl::reg::poseAt(back, 2'000'000'000, 0, "x");
  CHECK(mid.translation().x() == Approx(20).margin(1e-3));
  CHECK(angleErrorDeg(mid, poseOf(20, 20, 10)) < 1e-4);
  CHECK_THROWS_WITH(sl::reg::poseAt(back, 5'000'000'000, 100'000'000, "scan_9.ply"),
                    Catch::Contains("scan_9.ply: no robot pose"));
  {
    std::ofstream bad(dir / "bad.csv");
    bad << "stamp_ns,x,y,z,qx,qy,qz,qw\n1,0,0,0,0,0,0,1\n2,0,0,0,0,0,0,2\n";
  }
  CHECK_THROWS_WITH(sl::reg::readPoses((dir / "bad.csv").string()),
                    Catch::Contains("line 3: quaternion is not unit"));
  std::filesystem::remove_all(dir);
}
