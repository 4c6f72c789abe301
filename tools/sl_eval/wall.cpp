// wall: the paper's section 4.4 on the simulator. A sprayed-plaster wall
// larger than the field of view, 450 mm from the sensor; a 50 cm horizontal
// pass (3+3_vertical, camera sim_top, compensation along x) and a 30 cm
// vertical pass over the middle of it (3+3_horizontal, camera sim_left,
// compensation along y) at 12.5 mm/s, scanned through the daemon's ScanEngine
// with requests as a user sends them; the scans registered by sl_register's
// library (pairwise and multi-way) and compared with the simulator's exact
// surface.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <mutex>
#include <numeric>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "common.h"
#include "eval.h"
#include "plots.h"
#include "common/ply.h"
#include "registration.h"
#include "scan_files.h"
#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"
#include "sl/drivers/sim.h"
#include "sl/pipeline/calibration.h"
#include "sl/pipeline/motion_compensation.h"

namespace sl::eval {

namespace {

constexpr double kSpeedMmS = 12.5;    // paper: about 0.0125 m/s
constexpr double kScanRateHz = 5.0;   // 3+3 at 30 fps
constexpr double kWallDistance = 450; // mm, within the paper's 0.3-0.5 m
constexpr double kCellMm = 1.0;
constexpr double kWallWidth = 1000;   // mm along x: -250 .. 750
constexpr double kWallHeight = 700;   // mm along y: -350 .. 350
constexpr double kHorizontalLength = 500;
constexpr double kVerticalLength = 300;
constexpr int kSubsample = 3;         // keep every 3rd pixel of each row and column
constexpr double kPi = 3.14159265358979323846;

// Gaussian-filtered white noise scaled to rms_mm (sigma in cells).
cv::Mat smoothNoise(int rows, int cols, double sigma_cells, double rms_mm, std::uint64_t seed) {
  cv::Mat noise(rows, cols, CV_32FC1);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0, 1);
  cv::Mat smooth;
  cv::GaussianBlur(noise, smooth, cv::Size(0, 0), sigma_cells, sigma_cells, cv::BORDER_REFLECT);
  cv::Scalar mean, stddev;
  cv::meanStdDev(smooth, mean, stddev);
  smooth = (smooth - mean[0]) * (rms_mm / stddev[0]);
  return smooth;
}

// Sprayed plaster: bumps of a few mm (12 mm correlation), ridges (elongated
// along a slant, 3 x 12 mm), and fine roughness (1.5 mm).
cv::Mat plasterRelief(int rows, int cols) {
  cv::Mat bumps = smoothNoise(rows, cols, 12 / kCellMm, 1.2, 41);
  cv::Mat ridges_raw(rows, cols, CV_32FC1);
  cv::RNG rng(42);
  rng.fill(ridges_raw, cv::RNG::NORMAL, 0, 1);
  cv::Mat ridges;
  cv::GaussianBlur(ridges_raw, ridges, cv::Size(0, 0), 12 / kCellMm, 3 / kCellMm);
  cv::Mat rotation = cv::getRotationMatrix2D(cv::Point2f(cols / 2.f, rows / 2.f), 30, 1.0);
  cv::warpAffine(ridges, ridges, rotation, ridges.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  cv::Scalar mean, stddev;
  cv::meanStdDev(ridges, mean, stddev);
  ridges = (ridges - mean[0]) * (0.6 / stddev[0]);
  cv::Mat fine = smoothNoise(rows, cols, 1.5 / kCellMm, 0.05, 43);
  return bumps + ridges + fine;
}

drivers::SimHeightField makeWall() {
  drivers::SimHeightField f;
  f.origin = Eigen::Vector3d(250, 0, kWallDistance);
  f.normal = Eigen::Vector3d(0, 0, -1);
  f.x_axis = Eigen::Vector3d(1, 0, 0);
  f.width_mm = kWallWidth;
  f.length_mm = kWallHeight;
  f.cell_mm = kCellMm;
  f.albedo = 0.8;
  f.heights_mm = plasterRelief(int(std::lround(kWallHeight / kCellMm)) + 1,
                               int(std::lround(kWallWidth / kCellMm)) + 1);
  return f;
}

// Signed distance (mm) of a scene point from the height field's surface
// (positive towards the sensor), to first order in the surface slope:
// (h - H(a, b)) / sqrt(1 + |grad H|^2), H bilinear as the simulator renders
// it (its height-field ray casting is exact on the bilinear surface).
// NaN outside the field.
double surfaceDistance(const drivers::SimHeightField& f, const Eigen::Vector3d& p) {
  const Eigen::Vector3d n = f.normal.normalized();
  const Eigen::Vector3d x = (f.x_axis - n * n.dot(f.x_axis)).normalized();
  const Eigen::Vector3d y = n.cross(x);
  const Eigen::Vector3d d = p - f.origin;
  const double u = (d.dot(x) + f.width_mm / 2) / f.cell_mm;
  const double v = (d.dot(y) + f.length_mm / 2) / f.cell_mm;
  const cv::Mat& h = f.heights_mm;
  if (!(u >= 0 && v >= 0 && u < h.cols - 1 && v < h.rows - 1))
    return std::numeric_limits<double>::quiet_NaN();
  const int c = int(u), r = int(v);
  const double fu = u - c, fv = v - r;
  const double h00 = h.at<float>(r, c), h01 = h.at<float>(r, c + 1);
  const double h10 = h.at<float>(r + 1, c), h11 = h.at<float>(r + 1, c + 1);
  const double H = (1 - fv) * ((1 - fu) * h00 + fu * h01) + fv * ((1 - fu) * h10 + fu * h11);
  const double gu = ((1 - fv) * (h01 - h00) + fv * (h11 - h10)) / f.cell_mm;
  const double gv = ((1 - fu) * (h10 - h00) + fu * (h11 - h01)) / f.cell_mm;
  return (d.dot(n) - H) / std::sqrt(1 + gu * gu + gv * gv);
}

struct PassPlan {
  std::string name;     // horizontal | vertical
  std::string pattern;  // fringes along the motion
  std::string camera;   // baseline across the fringes
  pipeline::MotionCompensationOptions::Axis axis;
  Eigen::Vector3d velocity;             // mm/s, sensor frame (sim_top)
  std::vector<Eigen::Isometry3d> bases; // sensor pose at each scan's first image (scene frame)
};

struct Captured {
  std::string pattern, camera;  // as the engine reported them
  int pass = 0;
  int index = 0;
  std::int64_t stamp_ns = 0;
  std::vector<Eigen::Vector3f> points;  // mm, triangulating camera frame
};

struct Stats {
  std::size_t count = 0;
  double mean = 0, std = 0, p005 = 0, p995 = 0, within = 0, abs_p995 = 0;
};

Stats statsOf(const std::vector<double>& d) {
  Stats s;
  s.count = d.size();
  if (d.empty()) return s;
  s.mean = std::accumulate(d.begin(), d.end(), 0.0) / double(d.size());
  double ss = 0;
  std::size_t in = 0;
  std::vector<double> a;
  a.reserve(d.size());
  for (double v : d) {
    ss += (v - s.mean) * (v - s.mean);
    in += std::abs(v) <= 0.5;
    a.push_back(std::abs(v));
  }
  s.std = std::sqrt(ss / double(d.size()));
  s.within = 100.0 * double(in) / double(d.size());
  s.p005 = percentile(d, 0.005);
  s.p995 = percentile(d, 0.995);
  s.abs_p995 = percentile(a, 0.995);
  return s;
}

double angleDeg(const Eigen::Matrix3d& R) { return Eigen::AngleAxisd(R).angle() * 180 / kPi; }

using Say = std::function<void(const std::string&)>;

const char* passName(int pass) { return pass == 0 ? "horizontal" : "vertical"; }

std::string scanName(const Captured& c) {
  char name[32];
  std::snprintf(name, sizeof name, "%s_%02d", c.pass == 0 ? "h" : "v", c.index);
  return name;
}

// The scans as sl_register reads them: DIR/horizontal/h_NN.ply and
// DIR/vertical/v_NN.ply (mm, the triangulating camera's frame, stamped),
// with DIR/truth.tum (true poses) and DIR/prior.tum (the robot poses of the
// prior), so that `sl_register --poses DIR/prior.tum --out OUT
// DIR/horizontal DIR/vertical` registers them as this experiment does.
void saveScans(const std::string& dir, const std::vector<Captured>& captured,
               const std::vector<Eigen::Isometry3d>& truth,
               const std::vector<Eigen::Isometry3d>& prior) {
  std::vector<reg::StampedPose> true_poses, prior_poses;
  for (std::size_t i = 0; i < captured.size(); ++i) {
    const Captured& c = captured[i];
    const std::string folder = dir + "/" + passName(c.pass);
    std::filesystem::create_directories(folder);
    pipeline::PointCloud cloud;
    cloud.width = int(c.points.size());
    cloud.height = 1;
    cloud.stamp_ns = c.stamp_ns;
    cloud.frame_id = c.camera;
    for (const Eigen::Vector3f& p : c.points) cloud.points.push_back({p.x(), p.y(), p.z(), 0.0f});
    tools::writePly(cloud, folder + "/" + scanName(c) + ".ply", tools::LengthUnit::kMillimetre);
    true_poses.push_back({c.stamp_ns, truth[i]});
    prior_poses.push_back({c.stamp_ns, prior[i]});
  }
  reg::writeTum(dir + "/truth.tum", true_poses);
  reg::writeTum(dir + "/prior.tum", prior_poses);
}

// Scans saved by saveScans, with their true poses; the counts must be those
// asked for.
std::vector<Captured> loadScans(const std::string& dir, int horizontal_scans, int vertical_scans,
                                std::vector<Eigen::Isometry3d>& truth) {
  const std::vector<reg::StampedPose> true_poses = reg::readPoses(dir + "/truth.tum");
  std::vector<Captured> captured;
  for (int pass = 0; pass < 2; ++pass) {
    const std::vector<std::string> files = reg::listScanFiles(dir + "/" + passName(pass));
    const int expected = pass == 0 ? horizontal_scans : vertical_scans;
    if (int(files.size()) != expected)
      throw std::runtime_error("wall: " + dir + "/" + passName(pass) + " holds " +
                               std::to_string(files.size()) + " scans, the scan count asks for " +
                               std::to_string(expected));
    for (std::size_t k = 0; k < files.size(); ++k) {
      const reg::ScanFile file = reg::readScanFile(files[k]);
      Captured c;
      c.pass = pass;
      c.index = int(k);
      c.stamp_ns = file.stamp_ns;
      c.points = file.points;
      truth.push_back(reg::poseAt(true_poses, file.stamp_ns, 0, "the true pose of " + files[k]));
      captured.push_back(std::move(c));
    }
  }
  return captured;
}

// The two passes through the daemon's ScanEngine: the scans (horizontal
// pass, then vertical) with each scan's true pose T_scene_scan appended to
// `truth`.
std::vector<Captured> scanWall(const EvalOptions& options, const drivers::SimHeightField& wall,
                               int horizontal_scans, int vertical_scans,
                               std::vector<Eigen::Isometry3d>& truth, const Say& say) {
  const double spacing = kHorizontalLength / (horizontal_scans - 1);
  // The daemon's config for the two-camera simulated sensor (config/sim-motion.yaml),
  // with the wall as its scene; the robot (this experiment) moves the sensor.
  daemon::DaemonConfig config = daemon::loadConfig(std::string(SL_CONFIG_DIR) + "/sim-motion.yaml");
  config.sim.scene = {};
  config.sim.scene.height_fields.push_back(wall);
  config.sim.motion = {};
  config.sim.projector_gamma = options.projector_gamma;
  // The simulated cameras render a moving view in tens of ms per image (more
  // on a loaded machine): a software-triggered grab may take that long.
  config.software_trigger.grab_timeout_s = 120;
  say("setting up the simulated sensor (wall " + fmt(kWallWidth, 0) + " x " + fmt(kWallHeight, 0) +
      " mm)");
  const auto sim = drivers::SimulatedSensor::create(config.sim);
  say("sensor ready");

  // Camera frames relative to the sensor frame (sim_top), from the true rigs.
  const Eigen::Isometry3d top_to_sensor = Eigen::Isometry3d::Identity();
  const Eigen::Isometry3d left_to_sensor =
      pipeline::cameraToCamera(config.sim.second_camera->rig, config.sim.rig);
  // Each pass's camera faces the wall, its image axis along the motion: the
  // horizontal pass moves along sim_top's x (= the projector's x: the
  // projector is pitched about it), the vertical pass along sim_left's y (=
  // the projector's y: yawed about it), so that the motion runs along the
  // fringes in the projector (no change of phase) and along one image axis
  // (what the 1-D compensation models), at a constant distance from the
  // wall. The robot turns the sensor for the vertical pass so that sim_left
  // looks straight at the wall. (Moved along sim_top's y instead, sim_left,
  // turned 17 deg about both axes from sim_top, sees the scene move 0.09 px
  // across its fringes for every px along y, and the projector approach the
  // wall by 0.29 mm per mm: +0.3 mm of bias and fringe-periodic ripple.)
  const Eigen::Matrix3d vertical_rotation = left_to_sensor.linear().transpose();
  std::vector<PassPlan> plans(2);
  plans[0] = {"horizontal", "3+3_vertical", "sim_top", pipeline::MotionCompensationOptions::Axis::kX,
              Eigen::Vector3d(kSpeedMmS, 0, 0), {}};
  plans[1] = {"vertical", "3+3_horizontal", "sim_left", pipeline::MotionCompensationOptions::Axis::kY,
              left_to_sensor.linear() * Eigen::Vector3d(0, kSpeedMmS, 0), {}};
  for (int k = 0; k < horizontal_scans; ++k) {
    Eigen::Isometry3d b = Eigen::Isometry3d::Identity();
    b.translation() = Eigen::Vector3d(k * spacing, 0, 0);
    plans[0].bases.push_back(b);
  }
  // The vertical pass centred on the horizontal one's middle (x = 250 mm),
  // -150 .. 150 mm, sim_left as far from the wall as sim_top on the
  // horizontal pass.
  for (int k = 0; k < vertical_scans; ++k) {
    Eigen::Isometry3d b = Eigen::Isometry3d::Identity();
    b.linear() = vertical_rotation;
    const Eigen::Vector3d left_position(kHorizontalLength / 2,
                                        -kVerticalLength / 2 + k * kVerticalLength / (vertical_scans - 1), 0);
    b.translation() = left_position - vertical_rotation * left_to_sensor.translation();
    plans[1].bases.push_back(b);
  }

  std::mutex mutex;
  std::condition_variable arrived;
  std::vector<Captured> captured;
  int current_pass = 0, current_index = 0;
  daemon::ScanEngine engine(
      config, {sim->cameras(), sim->projector(), sim->triggerSource()},
      [&](const daemon::ScanResult& r) {
        Captured c;
        c.pattern = r.pattern;
        c.camera = r.camera_id;
        const pipeline::PointCloud& cloud = *r.cloud;
        c.stamp_ns = cloud.stamp_ns;
        for (int v = 0; v < cloud.height; v += kSubsample)
          for (int u = 0; u < cloud.width; u += kSubsample) {
            const pipeline::PointXYZI& p = cloud.points[std::size_t(v) * cloud.width + u];
            if (std::isfinite(p.z)) c.points.emplace_back(p.x, p.y, p.z);
          }
        std::lock_guard lock(mutex);
        c.pass = current_pass;
        c.index = current_index;
        captured.push_back(std::move(c));
        arrived.notify_all();
      });

  // The scans: per pass, the pattern, camera and compensation axis set by
  // requests; per scan, the robot places the sensor and the scan is
  // requested (software trigger, one scan), the sensor moving at 12.5 mm/s
  // during it. The scans kept are every (spacing / 2.5 mm)-th of the 5 Hz
  // stream a continuous pass would give.
  // The frame the compensation aligns to (the cloud's time): the config's
  // (config/sim-motion.yaml: 1, the middle of 3+3's fine set), -1 = the
  // middle of the 6 frames.
  const int reference_frame =
      config.motion.options.reference_frame < 0 ? 3 : config.motion.options.reference_frame;
  for (std::size_t p = 0; p < plans.size(); ++p) {
    const PassPlan& plan = plans[p];
    daemon::DaemonConfig settings = engine.config();
    settings.motion.enabled = true;
    settings.motion.options.axis = plan.axis;
    engine.applyRuntimeSettings(settings);
    drivers::SimMotion motion;
    motion.velocity_mm_s = plan.velocity;
    const Eigen::Isometry3d& camera_to_sensor = plan.camera == "sim_top" ? top_to_sensor : left_to_sensor;
    for (std::size_t k = 0; k < plan.bases.size(); ++k) {
      {
        std::lock_guard lock(mutex);
        current_pass = int(p);
        current_index = int(k);
      }
      sim->setMotion(plan.bases[k], motion);
      client::StartRequest request;
      request.pattern = plan.pattern;
      request.count = 1;
      request.trigger = client::TriggerMode::kSoftware;
      request.cameras = {plan.camera};
      request.motion_compensation = true;
      const std::size_t before = captured.size();
      const client::CommandResult started = engine.start(request);
      if (!started.accepted())
        throw std::runtime_error("wall: start request for " + plan.name + " scan " +
                                 std::to_string(k) + " refused: " + started.reason);
      for (;;) {
        std::unique_lock lock(mutex);
        if (arrived.wait_for(lock, std::chrono::seconds(10), [&] { return captured.size() > before; }))
          break;
        lock.unlock();
        const daemon::EngineStatus st = engine.status();
        if (st.state == client::ScanState::kIdle || st.state == client::ScanState::kError)
          throw std::runtime_error("wall: no cloud for " + plan.name + " scan " + std::to_string(k) +
                                   " (engine " + client::toString(st.state) + ", last error: " +
                                   st.last_error + ")");
        say("waiting for " + plan.name + " scan " + std::to_string(k + 1) + ": engine " +
            client::toString(st.state) + ", " + std::to_string(st.scans_done) + " done");
      }
      if (captured.back().pattern != plan.pattern || captured.back().camera != plan.camera)
        throw std::runtime_error("wall: " + plan.name + " scan " + std::to_string(k) + " came as " +
                                 captured.back().pattern + " / " + captured.back().camera +
                                 ", requested " + plan.pattern + " / " + plan.camera);
      for (int i = 0; i < 2000 && engine.status().state != client::ScanState::kIdle; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      truth.push_back(plan.bases[k] * motion.poseAt(reference_frame, config.sim.camera_fps) *
                      camera_to_sensor);
      say(plan.name + " scan " + std::to_string(k + 1) + "/" + std::to_string(plan.bases.size()) +
          ": " + std::to_string(captured.back().points.size()) + " points");
    }
  }
  return captured;
}

}  // namespace

EvalResult runWall(const EvalOptions& in) {
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - t_start).count(); };
  auto say = [&](const std::string& line) {
    std::fprintf(stderr, "wall: [%5.0f s] %s\n", seconds(), line.c_str());
  };
  const EvalOptions options = withDefaultScans(in, "wall");
  const int horizontal_scans = std::max(3, options.scans);
  const double spacing = kHorizontalLength / (horizontal_scans - 1);
  const int vertical_scans = std::max(2, int(std::lround(kVerticalLength / spacing)) + 1);

  const drivers::SimHeightField wall = makeWall();
  std::vector<Eigen::Isometry3d> truth;  // T_scene_scan per captured scan
  std::vector<Captured> captured;
  if (!options.load_scans_dir.empty()) {
    captured = loadScans(options.load_scans_dir, horizontal_scans, vertical_scans, truth);
    say("loaded " + std::to_string(captured.size()) + " scans from " + options.load_scans_dir);
  } else {
    captured = scanWall(options, wall, horizontal_scans, vertical_scans, truth, say);
  }
  const double scanning_s = seconds();

  // The scans on their own: every point at its scan's true pose (no
  // registration), so that a scan's errors are told from registration's.
  // Per pass, the distances' systematic shape over the image: a
  // least-squares fit d = c0 + c1 x + c2 y + c3 x^2 + c4 y^2 + c5 x y over
  // the points within 0.5 mm (x, y: the point in its camera's frame, in units
  // of 100 mm). A tilt or bowl common to the scans biases every edge between
  // overlapping scans the same way (ICP tilts one onto the other), which no
  // pose graph removes: it accumulates along the pass.
  std::vector<std::vector<double>> truth_per_pass(2);
  std::vector<Eigen::Matrix<double, 6, 6>> shape_normal(2, Eigen::Matrix<double, 6, 6>::Zero());
  std::vector<Eigen::Matrix<double, 6, 1>> shape_rhs(2, Eigen::Matrix<double, 6, 1>::Zero());
  for (std::size_t i = 0; i < captured.size(); ++i) {
    const Captured& c = captured[i];
    std::size_t gross = 0, off = 0, outside = 0;
    for (std::size_t k = 0; k < c.points.size(); ++k) {
      const double d = surfaceDistance(wall, truth[i] * c.points[k].cast<double>());
      if (!std::isfinite(d)) {
        ++outside;
        continue;
      }
      truth_per_pass[std::size_t(c.pass)].push_back(d);
      gross += std::abs(d) > 5;
      off += std::abs(d) > 0.5;
      if (std::abs(d) <= 0.5) {
        const double x = c.points[k].x() / 100, y = c.points[k].y() / 100;
        Eigen::Matrix<double, 6, 1> basis;
        basis << 1, x, y, x * x, y * y, x * y;
        shape_normal[std::size_t(c.pass)] += basis * basis.transpose();
        shape_rhs[std::size_t(c.pass)] += basis * d;
      }
    }
    say("scan " + std::to_string(i) + " (" + (c.pass == 0 ? "h" : "v") + std::to_string(c.index) +
        ") at its true pose: " + std::to_string(c.points.size()) + " points, " +
        std::to_string(off) + " beyond 0.5 mm, " + std::to_string(gross) + " beyond 5 mm, " +
        std::to_string(outside) + " off the wall");
  }
  std::vector<std::string> shape_lines;
  for (int pass = 0; pass < 2; ++pass) {
    if (shape_normal[std::size_t(pass)](0, 0) < 100) continue;
    const Eigen::Matrix<double, 6, 1> k =
        shape_normal[std::size_t(pass)].ldlt().solve(shape_rhs[std::size_t(pass)]);
    char line[320];
    std::snprintf(line, sizeof line,
                  "%s pass, scans at their true poses: distance = %.4f %+.4f x %+.4f y %+.4f x^2 "
                  "%+.4f y^2 %+.4f x y mm (x, y in the camera frame, 100 mm units)",
                  passName(pass), k[0], k[1], k[2], k[3], k[4], k[5]);
    say(line);
    shape_lines.push_back(line);
  }

  // The prior: robot poses with the errors of an arm's absolute positioning
  // (1 mm per axis, 0.1 deg per axis, seeded).
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0, 1);
  std::vector<reg::ScanInput> scans;
  for (std::size_t i = 0; i < captured.size(); ++i) {
    reg::ScanInput s;
    const Captured& c = captured[i];
    s.name = scanName(c);
    s.pass = c.pass;
    s.stamp_ns = c.stamp_ns;
    s.points = c.points;
    Eigen::Isometry3d error = Eigen::Isometry3d::Identity();
    error.linear() = (Eigen::AngleAxisd(radiansOf(0.1 * g(rng)), Eigen::Vector3d::UnitX()) *
                      Eigen::AngleAxisd(radiansOf(0.1 * g(rng)), Eigen::Vector3d::UnitY()) *
                      Eigen::AngleAxisd(radiansOf(0.1 * g(rng)), Eigen::Vector3d::UnitZ()))
                         .toRotationMatrix();
    error.translation() = Eigen::Vector3d(g(rng), g(rng), g(rng));
    s.initial = truth[i] * error;
    scans.push_back(std::move(s));
  }
  if (!options.save_scans_dir.empty()) {
    std::vector<Eigen::Isometry3d> prior;
    for (const reg::ScanInput& s : scans) prior.push_back(s.initial);
    saveScans(options.save_scans_dir, captured, truth, prior);
    say("scans saved to " + options.save_scans_dir);
  }

  EvalResult result;
  std::ostringstream md;
  struct Row {
    std::string method, pass;
    Stats stats;
    double drift_mm = 0, drift_deg = 0;
  };
  std::vector<Row> rows;
  std::vector<std::string> refused_lines, edge_lines;
  {
    std::vector<double> merged = truth_per_pass[0];
    merged.insert(merged.end(), truth_per_pass[1].begin(), truth_per_pass[1].end());
    rows.push_back({"true poses", "horizontal", statsOf(truth_per_pass[0]), 0, 0});
    rows.push_back({"true poses", "vertical", statsOf(truth_per_pass[1]), 0, 0});
    rows.push_back({"true poses", "merged", statsOf(merged), 0, 0});
  }
  const double cols_mm = kWallWidth, rows_mm = kWallHeight;
  // One multi-way registration; the pairwise chain it starts from is the
  // pairwise result (as a separate pairwise run gives it).
  reg::RegisterOptions ro;
  ro.multiway = true;
  const auto t0 = Clock::now();
  double chain_s = 0;
  const reg::RegisterResult multiway_result = reg::registerScans(scans, ro, [&](const std::string& line) {
    if (line.rfind("pairwise chain", 0) == 0)
      chain_s = std::chrono::duration<double>(Clock::now() - t0).count();
    if (line.rfind("ICP", 0) != 0) say("registration: " + line);
  });
  const double registration_s = std::chrono::duration<double>(Clock::now() - t0).count();
  say("registered in " + fmt(registration_s, 1) + " s (pairwise chain " + fmt(chain_s, 1) + " s of it)");
  result.metrics["pairwise_registration_s"] = chain_s;
  result.metrics["multiway_registration_s"] = registration_s;
  for (const bool multiway : {false, true}) {
    const std::string method = multiway ? "multiway" : "pairwise";
    const reg::RegisterResult& r = multiway ? multiway_result : *multiway_result.pairwise;
    for (const std::string& refused : r.refused) refused_lines.push_back(method + ": " + refused);
    // Each kept edge's measurement against the truth (the error of
    // T_target_source in the source's frame): a bias common to the edges
    // accumulates along the pass whatever the pose graph does.
    for (const reg::EdgeKind kind :
         {reg::EdgeKind::kNeighbour, reg::EdgeKind::kSkip, reg::EdgeKind::kCrossPass}) {
      Eigen::Vector3d t_sum = Eigen::Vector3d::Zero(), r_sum = Eigen::Vector3d::Zero();
      double t2 = 0, r2 = 0;
      int count = 0;
      for (const reg::EdgeReport& e : r.edges) {
        if (e.kind != kind || !e.accepted || e.pruned) continue;
        const Eigen::Isometry3d tru = truth[std::size_t(e.target)].inverse() * truth[std::size_t(e.source)];
        const Eigen::Isometry3d err = tru.inverse() * Eigen::Isometry3d(e.transform);
        const Eigen::AngleAxisd aa(err.linear());
        const Eigen::Vector3d rv = aa.axis() * aa.angle() * 180 / kPi;
        t_sum += err.translation();
        r_sum += rv;
        t2 += err.translation().squaredNorm();
        r2 += rv.squaredNorm();
        ++count;
      }
      if (count == 0) continue;
      const Eigen::Vector3d tm = t_sum / count, rm = r_sum / count;
      char line[320];
      std::snprintf(line, sizeof line,
                    "%s: %d kept %s edges against the truth: translation mean (%.3f, %.3f, %.3f) "
                    "mm, RMS %.3f mm; rotation mean (%.4f, %.4f, %.4f) deg, RMS %.4f deg",
                    method.c_str(), count, reg::toString(kind), tm.x(), tm.y(), tm.z(),
                    std::sqrt(t2 / count), rm.x(), rm.y(), rm.z(), std::sqrt(r2 / count));
      say(line);
      edge_lines.push_back(line);
    }
    // The estimate in the scene frame, held at the first scan's true pose.
    const Eigen::Isometry3d fix = truth[0] * r.poses[0].inverse();
    std::vector<std::vector<double>> per_pass(2);
    cv::Mat sum = cv::Mat::zeros(int(rows_mm), int(cols_mm), CV_32FC1);
    cv::Mat count = cv::Mat::zeros(int(rows_mm), int(cols_mm), CV_32FC1);
    for (std::size_t i = 0; i < scans.size(); ++i) {
      if (!r.registered[i]) continue;
      const Eigen::Isometry3d T = fix * r.poses[i];
      for (const Eigen::Vector3f& q : scans[i].points) {
        const Eigen::Vector3d p = T * q.cast<double>();
        const double d = surfaceDistance(wall, p);
        if (!std::isfinite(d)) continue;
        per_pass[std::size_t(scans[i].pass)].push_back(d);
        const int px = int(std::floor(p.x() + 250)), py = int(std::floor(p.y() + 350));
        if (px >= 0 && py >= 0 && px < sum.cols && py < sum.rows) {
          sum.at<float>(py, px) += float(d);
          count.at<float>(py, px) += 1;
        }
      }
    }
    auto drift = [&](std::size_t first, std::size_t last) {
      // A refused end scan has no estimated pose: no drift.
      if (!r.registered[first] || !r.registered[last])
        return std::pair<double, double>{std::numeric_limits<double>::quiet_NaN(),
                                         std::numeric_limits<double>::quiet_NaN()};
      const Eigen::Isometry3d est = r.poses[first].inverse() * r.poses[last];
      const Eigen::Isometry3d tru = truth[first].inverse() * truth[last];
      const Eigen::Isometry3d e = tru.inverse() * est;
      return std::pair<double, double>{e.translation().norm(), angleDeg(e.linear())};
    };
    std::size_t first_v = 0;
    while (first_v < scans.size() && scans[first_v].pass == 0) ++first_v;
    const std::size_t last_h = first_v - 1, last = scans.size() - 1;
    std::vector<double> merged = per_pass[0];
    merged.insert(merged.end(), per_pass[1].begin(), per_pass[1].end());
    const auto dh = drift(0, last_h), dv = drift(first_v, last), dm = drift(0, last);
    rows.push_back({method, "horizontal", statsOf(per_pass[0]), dh.first, dh.second});
    rows.push_back({method, "vertical", statsOf(per_pass[1]), dv.first, dv.second});
    rows.push_back({method, "merged", statsOf(merged), dm.first, dm.second});
    if (!options.out_dir.empty()) {
      cv::Mat mean_map(sum.size(), CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
      for (int y = 0; y < sum.rows; ++y)
        for (int x = 0; x < sum.cols; ++x)
          if (count.at<float>(y, x) > 0)
            mean_map.at<float>(y, x) = sum.at<float>(y, x) / count.at<float>(y, x);
      const std::string path = plotPath(options, "wall_" + method + "_distances.png");
      writeSignedMap(path, mean_map, 0.5,
                     "wall, " + method + ": signed distance to the true surface (1 mm cells)", "mm");
      result.plots.push_back(path);
    }
  }
  const double total_s = seconds();

  md << "### Wall (paper 4.4): " << horizontal_scans << " scans over a " << kHorizontalLength
     << " mm horizontal pass and " << vertical_scans << " over a " << kVerticalLength
     << " mm vertical pass, " << fmt(spacing, 1) << " mm apart (every "
     << fmt(spacing / (kSpeedMmS / kScanRateHz), 0) << "th scan of the 5 Hz stream at "
     << kSpeedMmS << " mm/s), wall " << kWallDistance
     << " mm away with plaster relief (bumps 1.2 mm RMS, ridges 0.6 mm, roughness 0.05 mm; "
        "a height field of 1 mm cells)\n\n";
  md << "Signed distances (mm) of the registered scans' points (every " << kSubsample
     << "rd pixel) to the simulator's exact surface, the first scan held at its true pose; drift = "
        "error of the last scan's pose relative to the pass's first (merged: to the first scan "
        "of all). Prior: robot poses with 1 mm / 0.1 deg errors per axis. \"true poses\": every "
        "scan at its true pose, no registration (the scans' own errors).\n\n";
  md << "| registration | pass | points | mean | std | 0.5 % | 99.5 % | within +-0.5 mm | drift mm | "
        "drift deg |\n|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& row : rows)
    md << "| " << row.method << " | " << row.pass << " | " << row.stats.count << " | "
       << fmt(row.stats.mean, 3) << " | " << fmt(row.stats.std, 3) << " | " << fmt(row.stats.p005, 3)
       << " | " << fmt(row.stats.p995, 3) << " | " << fmt(row.stats.within, 2) << " % | "
       << fmt(row.drift_mm, 3) << " | " << fmt(row.drift_deg, 4) << " |\n";
  md << "| paper (TLS C2M), pairwise | R1 vertical | | 0.01 | 0.53 | -1.63 | 1.36 | | | |\n"
        "| paper (TLS C2M), pairwise | R2 vertical | | 0.01 | 0.65 | -1.94 | 1.65 | | | |\n"
        "| paper (TLS C2M), pairwise | R1 horizontal | | 0.07 | 0.71 | -2.43 | 1.83 | | | |\n"
        "| paper (TLS C2M), pairwise | R2 horizontal (printed R1) | | 0.1 | 1.06 | -2.99 | 2.87 | | | |\n";
  md << "\nScanning " << fmt(scanning_s, 0) << " s, registration "
     << fmt(result.metrics["multiway_registration_s"], 0) << " s (multi-way, its pairwise chain "
     << fmt(result.metrics["pairwise_registration_s"], 0) << " s of it), total " << fmt(total_s, 0)
     << " s.\n";
  for (const std::string& line : shape_lines) md << "\nshape: " << line;
  if (!shape_lines.empty()) md << "\n";
  for (const std::string& line : edge_lines) md << "\nedges: " << line;
  if (!edge_lines.empty()) md << "\n";
  for (const std::string& line : refused_lines) md << "\nrefused: " << line;
  if (!refused_lines.empty()) md << "\n";
  for (const std::string& plot : result.plots) md << "\nheat map: " << plot;
  md << "\n\n";
  for (const Row& row : rows) {
    const std::string key = (row.method == "true poses" ? "truth" : row.method) + "_" + row.pass + "_";
    result.metrics[key + "within_0.5mm_pct"] = row.stats.within;
    result.metrics[key + "p99_5_mm"] = row.stats.abs_p995;
    result.metrics[key + "mean_mm"] = row.stats.mean;
    result.metrics[key + "std_mm"] = row.stats.std;
    result.metrics[key + "drift_mm"] = row.drift_mm;
    result.metrics[key + "drift_deg"] = row.drift_deg;
    if (row.method == "true poses") continue;  // not a registration: no wall: line
    char line[256];
    std::snprintf(line, sizeof line,
                  "wall: %s %s within_0.5mm_pct=%.2f p99_5_mm=%.3f drift_mm=%.3f drift_deg=%.4f\n",
                  row.method.c_str(), row.pass.c_str(), row.stats.within, row.stats.abs_p995,
                  row.drift_mm, row.drift_deg);
    md << line;
  }
  result.metrics["refused_scans"] = double(refused_lines.size());
  result.metrics["scans"] = double(scans.size());
  result.metrics["total_s"] = total_s;
  result.markdown = md.str();
  // The plots are named in the markdown, before the wall: lines that end it.
  result.plots.clear();
  return result;
}

}  // namespace sl::eval
