// End to end: sl_sensord runs on the simulated sensor in a child process; the
// test asks for scans through the DDS request topic, receives the clouds over
// DDS and compares them with the simulator's ground truth.
//
// Expected error, from the simulator's noise model (drivers/sim.h) and the
// 3-step phase-shift estimator (paper eq. 1-2):
//   per-frame intensity noise (8-bit DN^2):  s_I^2 = g*A + r^2 + 1/12
//     (shot noise g*S averaged over the three frames is g*A; 1/12 is the
//      8-bit quantisation), A = offset, B = modulation of the pixel;
//   wrapped-phase noise of the 3-step estimator:  s_phi = sqrt(2/3) * s_I / B;
//   projector coordinate:  s_p = lambda / (2 pi) * s_phi,  lambda = 1824/16 px;
//   depth along the camera ray:  s_z = s_p / |dp/dz|, with dp/dz from the rig
//     geometry at the true point; 3-D error s_3d = s_z * |X| / z.
// The test computes the prediction per pixel from the measured A (the cloud's
// intensity), B = A - ambient * albedo (a 0.5 + 0.5 cos pattern has A - ambient
// = B), and checks that the measured RMS error over the plane lies within
// 0.9..1.1 of the predicted RMS (measured: 0.483 mm against 0.482 mm
// predicted; the margin covers the 8-bit pattern quantisation and the
// projector-distortion correction residuals; the lower bound proves the noise
// is really there), the same for the residual RMS of a plane fitted to the
// measured points, the mean error (bias) is below 0.05 mm
// and at most 0.1 % of points are outliers (> 10 predicted sigma; wrong fringe
// order).
#include "support/time_scale.h"
#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <optional>
#include <map>
#include <mutex>
#include <thread>

#include <sys/socket.h>
#include <sys/un.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include "daemon_process.h"
#include "geometry_msgs/msg/TwistStamped.h"
#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/files/calibration_io.h"
#include "sl/client/client.h"
#include "sl/dds/dds.h"
#include "sl_msgs/msg/CommandReply.h"
#include "sl_msgs/msg/CommandRequest.h"
#include "sl_msgs/msg/ImageSet.h"
#include "sl_msgs/msg/ProjectorMaps.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/scan_processor.h"
#include "sl/pipeline/triangulator.h"
#include "sl/daemon/config.h"
#include "sl/drivers/recording.h"
#include "sl/drivers/sim.h"

using namespace std::chrono_literals;
using sl::client::Command;
// Waits and upper bounds on time: x10 in sanitizer builds.
using sl::test::kTimeScale;
using sl::test::scaledBound;

namespace {

struct PlaneStats {
  std::size_t points = 0;
  std::size_t outliers = 0;
  double rms_error_mm = 0;
  double mean_error_mm = 0;
  double predicted_rms_mm = 0;
  double plane_fit_rms_mm = 0;
  double predicted_plane_fit_rms_mm = 0;
  double max_inlier_error_mm = 0;
};

PlaneStats comparePlane(const sl::pipeline::PointCloud& cloud, const sl::daemon::DaemonConfig& config,
                        const sl::drivers::SimGroundTruth& gt, bool rows = false) {
  const auto& sim = config.sim;
  const sl::drivers::SimPlane& plane = sim.scene.planes.at(0);
  const Eigen::Vector3d n = plane.normal.normalized();
  const auto& rig = sim.rig;
  const double lambda =
      config.patterns.at(0).finestPeriod(rows ? rig.projector.height : rig.projector.width);
  const double read2 = sim.read_noise_dn * sim.read_noise_dn;

  PlaneStats s;
  double sum_err2 = 0, sum_err = 0, sum_pred2 = 0, sum_perp2 = 0;
  std::vector<Eigen::Vector3d> measured;
  for (int r = 0; r < cloud.height; ++r) {
    for (int c = 0; c < cloud.width; ++c) {
      const auto& p = cloud.points[std::size_t(r) * cloud.width + c];
      const cv::Vec3f g = gt.xyz_mm.at<cv::Vec3f>(r, c);
      if (!std::isfinite(p.z) || !std::isfinite(g[2])) continue;
      const Eigen::Vector3d x_gt(g[0], g[1], g[2]);
      if (std::abs(n.dot(x_gt - plane.point)) > 1e-3) continue;  // not on the plane
      // Predicted 3-D error of this pixel.
      const double A = p.intensity;
      const double B = A - sim.ambient_dn * plane.albedo;
      if (B <= 1) continue;
      const double sigma_i = std::sqrt(sim.gain_dn_per_electron * A + read2 + 1.0 / 12);
      const double sigma_phi = std::sqrt(2.0 / 3.0) * sigma_i / B;
      const double sigma_p = lambda / (2 * M_PI) * sigma_phi;
      const double dz = 0.5;
      const Eigen::Vector3d ray = x_gt / x_gt.z();
      // The projector coordinate the pattern encodes: column (or row).
      auto projectorColumn = [&](double z) {
        const Eigen::Vector2d p = rig.projector.project(rig.R * (z * ray) + rig.t);
        return rows ? p.y() : p.x();
      };
      const double dp_dz = (projectorColumn(x_gt.z() + dz) - projectorColumn(x_gt.z() - dz)) / (2 * dz);
      const double sigma_3d = sigma_p / std::abs(dp_dz) * ray.norm();
      const Eigen::Vector3d x(p.x, p.y, p.z);
      const double err = (x - x_gt).norm();
      if (err > 10 * sigma_3d) {
        ++s.outliers;
        continue;
      }
      ++s.points;
      sum_err2 += err * err;
      sum_err += (x.z() - x_gt.z()) * ray.norm();
      sum_pred2 += sigma_3d * sigma_3d;
      const double cos_ray_normal = std::abs(ray.normalized().dot(n));
      sum_perp2 += sigma_3d * sigma_3d * cos_ray_normal * cos_ray_normal;
      s.max_inlier_error_mm = std::max(s.max_inlier_error_mm, err);
      measured.push_back(x);
    }
  }
  REQUIRE(s.points > 100000);
  s.rms_error_mm = std::sqrt(sum_err2 / s.points);
  s.mean_error_mm = sum_err / s.points;
  s.predicted_rms_mm = std::sqrt(sum_pred2 / s.points);
  s.predicted_plane_fit_rms_mm = std::sqrt(sum_perp2 / s.points);
  // Least-squares plane through the measured points.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& x : measured) centroid += x;
  centroid /= double(measured.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& x : measured) scatter += (x - centroid) * (x - centroid).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  const Eigen::Vector3d normal = eig.eigenvectors().col(0);
  double sum_res2 = 0;
  for (const auto& x : measured) sum_res2 += std::pow(normal.dot(x - centroid), 2);
  s.plane_fit_rms_mm = std::sqrt(sum_res2 / measured.size());
  return s;
}

// A client of the daemon on namespace `ns`, once the daemon answers (bounded).
std::unique_ptr<sl::client::SensorClient> connect(const std::string& ns, bool points = true) {
  sl::client::ClientOptions options;
  options.ns = ns;
  options.subscribe_points = points;
  auto client = std::make_unique<sl::client::SensorClient>(options);
  REQUIRE(client->waitForDaemon(scaledBound(20s)));
  return client;
}

// Requests `count` scans of `pattern`; returns the time before the request:
// clouds stamped after it belong to this request.
std::int64_t startScans(sl::client::SensorClient& client, const std::string& pattern, int count) {
  const std::int64_t t0 = sl::test::nowNs();
  const auto reply = client.request(Command::kStart, pattern, count, scaledBound(5s));
  REQUIRE(reply);
  REQUIRE(reply->accepted);
  return t0;
}

}  // namespace

TEST_CASE("sl_sensord scans the simulated scene over DDS within the noise-model bounds") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("e2e");
  const std::string config_path = sl::test::writeTestConfig(ns);
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(config_path);

  sl::test::DaemonProcess daemon(config_path);
  REQUIRE(daemon.started());

  const auto client_owner = connect(ns);
  sl::client::SensorClient& client = *client_owner;

  SECTION("three scans match the ground truth") {
    const auto t0 = startScans(client, "3+3_horizontal", 3);

    const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
    const auto& gt = sim->groundTruth();
    for (int i = 0; i < 3; ++i) {
      const auto cloud = client.receiveCloud(t0, scaledBound(10s));
      REQUIRE(cloud);
      CHECK(cloud->width == 1440);
      CHECK(cloud->height == 1080);
      CHECK(cloud->frame_id == config.dds.frame_id);
      const PlaneStats s = comparePlane(*cloud, config, gt);
      INFO("scan " << i + 1 << ": plane points " << s.points << ", outliers " << s.outliers
                   << ", rms " << s.rms_error_mm << " mm (predicted " << s.predicted_rms_mm
                   << "), bias " << s.mean_error_mm << " mm, plane-fit rms " << s.plane_fit_rms_mm
                   << " mm (predicted " << s.predicted_plane_fit_rms_mm << "), max inlier error "
                   << s.max_inlier_error_mm << " mm");
      WARN("scan " << i + 1 << ": rms " << s.rms_error_mm << " mm (predicted "
                   << s.predicted_rms_mm << "), bias " << s.mean_error_mm << " mm, plane-fit rms "
                   << s.plane_fit_rms_mm << " (predicted " << s.predicted_plane_fit_rms_mm
                   << "), outliers " << s.outliers << " of " << s.points + s.outliers);
      CHECK(s.rms_error_mm < 1.1 * s.predicted_rms_mm);
      CHECK(s.rms_error_mm > 0.9 * s.predicted_rms_mm);
      CHECK(s.plane_fit_rms_mm < 1.1 * s.predicted_plane_fit_rms_mm);
      CHECK(s.plane_fit_rms_mm > 0.9 * s.predicted_plane_fit_rms_mm);
      CHECK(std::abs(s.mean_error_mm) < 0.05);
      CHECK(s.outliers < 0.001 * (s.points + s.outliers));
      CHECK(s.rms_error_mm < 1.0);  // sub-millimetre
    }
    const auto status = client.status(scaledBound(3s));
    REQUIRE(status);
  }

  SECTION("requests are answered and rejected with reasons") {
    auto reply = client.request(Command::kStart, "no_such_pattern", 1, scaledBound(5s));
    REQUIRE(reply);
    CHECK_FALSE(reply->accepted);
    CHECK(reply->code == sl::client::CommandResult::Code::kUnknownPattern);
    CHECK(reply->reason.find("no_such_pattern") != std::string::npos);
    CHECK(reply->patterns.size() == config.patterns.size());

    reply = client.request(Command::kListPatterns, "", 0, scaledBound(5s));
    REQUIRE(reply);
    CHECK(reply->accepted);
    CHECK(reply->patterns == std::vector<std::string>{"3+3_horizontal", "3+3_both"});
    reply = client.request(Command::kGetConfig, "", 0, scaledBound(5s));
    REQUIRE(reply);
    CHECK(reply->accepted);
    CHECK(reply->detail.find("namespace: " + ns) != std::string::npos);

    reply = client.request(Command::kStart, "", -2, scaledBound(5s));
    REQUIRE(reply);
    CHECK(reply->code == sl::client::CommandResult::Code::kInvalidCount);

    reply = client.request(Command::kStop, "", 0, scaledBound(5s));
    REQUIRE(reply);
    CHECK(reply->code == sl::client::CommandResult::Code::kNotRunning);

    reply = client.request(Command::kStart, "3+3_both", 0, scaledBound(5s));  // continuous
    REQUIRE(reply);
    CHECK(reply->accepted);
    reply = client.request(Command::kStart, "3+3_horizontal", 1, scaledBound(5s));
    REQUIRE(reply);
    CHECK(reply->code == sl::client::CommandResult::Code::kBusy);
    const auto t0 = sl::test::nowNs();
    CHECK(client.receiveCloud(t0, scaledBound(10s)));  // the continuous scan delivers
    reply = client.request(Command::kStop, "", 0, scaledBound(5s));
    REQUIRE(reply);
    CHECK(reply->accepted);
    reply = client.request(Command::kSetPattern, "3+3_horizontal", 0, scaledBound(5s));
    REQUIRE(reply);
    CHECK(reply->accepted);
  }

  SECTION("several clients at once each get exactly one reply, their own") {
    // A raw reader of the reply topic sees every reply of every client.
    sl::dds::Participant participant(0);
    sl::dds::Topic<sl_msgs_msg_dds__CommandReply_> topic(participant, "rr/" + ns + "/commandReply",
                                                   sl_msgs_msg_dds__CommandReply__desc);
    sl::dds::Reader<sl_msgs_msg_dds__CommandReply_> replies(participant, topic,
                                                      sl::dds::Qos().reliable().keepLast(256));
    REQUIRE(replies.waitForWriters(1, DDS_SECS(10) * kTimeScale));
    constexpr int kClients = 3, kRequests = 5;
    std::vector<std::unique_ptr<sl::client::SensorClient>> clients;
    for (int c = 0; c < kClients; ++c) clients.push_back(connect(ns, /*points=*/false));
    // Each client asks for a pattern only it names; every request id is
    // used by every client (ids count from 1 per client).
    std::vector<std::thread> threads;
    std::atomic<int> own_replies{0};
    for (int c = 0; c < kClients; ++c)
      threads.emplace_back([&, c] {
        for (int r = 0; r < kRequests; ++r) {
          const std::string name = "client" + std::to_string(c) + "_request" + std::to_string(r);
          const auto reply = clients[c]->request(Command::kStart, name, 1, scaledBound(5s));
          if (reply && reply->code == sl::client::CommandResult::Code::kUnknownPattern &&
              reply->reason.find("'" + name + "'") != std::string::npos)
            ++own_replies;
        }
      });
    for (auto& t : threads) t.join();
    CHECK(own_replies == kClients * kRequests);
    // Exactly one reply per (client, request id) on the wire.
    // (Until all arrived, then a little longer to catch duplicates.)
    std::map<std::pair<std::string, std::uint64_t>, int> seen;
    auto deadline = std::chrono::steady_clock::now() + scaledBound(5s);
    bool all = false;
    while (std::chrono::steady_clock::now() < deadline) {
      if (!all && seen.size() == std::size_t(kClients * kRequests)) {
        all = true;
        deadline = std::chrono::steady_clock::now() + 300ms;
      }
      auto loan = replies.take(64);
      for (std::size_t i = 0; i < loan.size(); ++i)
        if (loan.isValid(i)) ++seen[{loan[i].client_id, loan[i].request_id}];
      if (loan.empty()) std::this_thread::sleep_for(20ms);
    }
    CHECK(seen.size() == std::size_t(kClients * kRequests));
    for (const auto& [key, count] : seen) {
      INFO("client " << key.first << " request " << key.second);
      CHECK(count == 1);
    }
  }

  SECTION("a reply written before the client's reader was matched still reaches it") {
    // A request from a participant with no reply reader at all: the daemon
    // answers it while no reader of the reply topic is matched (what happens
    // to a client whose reader the daemon discovers after its request).
    sl::dds::Participant participant(0);
    sl::dds::Topic<sl_msgs_msg_dds__CommandRequest_> request_topic(
        participant, "rq/" + ns + "/commandRequest", sl_msgs_msg_dds__CommandRequest__desc);
    sl::dds::Writer<sl_msgs_msg_dds__CommandRequest_> writer(
        participant, request_topic, sl::dds::Qos().reliable().keepLast(16).xcdr1());
    REQUIRE(writer.waitForReaders(1, DDS_SECS(10) * kTimeScale));
    const auto before = client.status(scaledBound(5s));
    REQUIRE(before);
    std::string client_id = "late_reader", empty;
    sl_msgs_msg_dds__CommandRequest_ request{};
    request.client_id = client_id.data();
    request.request_id = 7;
    request.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS;
    request.pattern = empty.data();
    request.recording = empty.data();
    REQUIRE(writer.write(request));
    const auto s = sl::test::statusWhen(
        client, [&](const auto& s) { return s.requests_answered != before->requests_answered; },
        scaledBound(5s));
    REQUIRE(s);
    REQUIRE(s->requests_answered == before->requests_answered + 1);
    // Only now a reader of the replies, as a client's: it gets that reply.
    sl::dds::Topic<sl_msgs_msg_dds__CommandReply_> reply_topic(
        participant, "rr/" + ns + "/commandReply", sl_msgs_msg_dds__CommandReply__desc);
    sl::dds::Reader<sl_msgs_msg_dds__CommandReply_> replies(
        participant, reply_topic, sl::dds::Qos().reliable().transientLocal().keepLast(64));
    REQUIRE(replies.waitForWriters(1, DDS_SECS(10) * kTimeScale));
    bool found = false;
    const auto deadline = std::chrono::steady_clock::now() + scaledBound(5s);
    while (!found && std::chrono::steady_clock::now() < deadline) {
      auto loan = replies.take(64);
      for (std::size_t i = 0; i < loan.size(); ++i)
        found = found || (loan.isValid(i) && loan[i].client_id == client_id &&
                          loan[i].request_id == 7 && loan[i].accepted);
      if (loan.empty()) std::this_thread::sleep_for(20ms);
    }
    CHECK(found);
  }

  // SIGTERM: a clean exit within 2 s.
  const auto started = std::chrono::steady_clock::now();
  const auto exit_status = daemon.terminate(5s);
  const auto elapsed = std::chrono::steady_clock::now() - started;
  REQUIRE(exit_status);
  CHECK(*exit_status == 0);
  CHECK(elapsed < scaledBound(2s));
}

TEST_CASE("sl_sensord sends READY=1 to systemd once it is up") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("notify");
  const std::string config_path = sl::test::writeTestConfig(ns);
  // A datagram socket standing in for systemd's notification socket.
  const std::string socket_path = "/tmp/sl_notify_" + ns;
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  REQUIRE(fd >= 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::snprintf(address.sun_path, sizeof address.sun_path, "%s", socket_path.c_str());
  ::unlink(socket_path.c_str());
  REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0);
  timeval receive_timeout{20 * kTimeScale, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &receive_timeout, sizeof receive_timeout);

  setenv("NOTIFY_SOCKET", socket_path.c_str(), 1);
  setenv("WATCHDOG_USEC", "300000", 1);  // 0.3 s: pings every 0.1 s while healthy
  sl::test::DaemonProcess daemon(config_path);
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  REQUIRE(daemon.started());
  char buffer[256] = {};
  const ssize_t n = ::recv(fd, buffer, sizeof buffer - 1, 0);
  CHECK(std::string(buffer, n > 0 ? n : 0) == "READY=1");
  // Watchdog pings follow, well within the interval systemd asked for.
  int pings = 0;
  const auto watch_start = std::chrono::steady_clock::now();
  while (pings < 5 && std::chrono::steady_clock::now() - watch_start < scaledBound(3s)) {
    const ssize_t m = ::recv(fd, buffer, sizeof buffer - 1, 0);
    if (m > 0 && std::string(buffer, m) == "WATCHDOG=1") ++pings;
  }
  const auto watch_elapsed = std::chrono::steady_clock::now() - watch_start;
  CHECK(pings == 5);
  CHECK(watch_elapsed < scaledBound(1500ms));  // 5 pings at 0.1 s intervals
  // The daemon answers requests once it said it is ready.
  const auto client_owner = connect(ns, /*points=*/false);
  sl::client::SensorClient& client = *client_owner;
  const auto status = client.status(scaledBound(5s));
  REQUIRE(status);
  CHECK(status->state == sl::client::ScanState::kIdle);
  const auto exit_status = daemon.terminate(5s);
  REQUIRE(exit_status);
  CHECK(*exit_status == 0);
  // STOPPING=1 comes after any watchdog pings still queued.
  std::string last;
  for (ssize_t m; (m = ::recv(fd, buffer, sizeof buffer - 1, MSG_DONTWAIT)) > 0;)
    last.assign(buffer, m);
  CHECK(last == "STOPPING=1");
  ::close(fd);
  ::unlink(socket_path.c_str());
}

// Pattern switching during a continuous scan (issue 7): horizontal -> both ->
// horizontal through the request topic. Every published projector-map sample
// must come from exactly one pattern: a horizontal scan encodes only columns
// (vp all NaN), a 'both' scan columns and rows; the patterns appear in the
// requested order, each at least twice. The switch takes effect at the next
// sequence boundary: the sequence in progress when the request is sent (it
// began less than one sequence period earlier) is still published with the
// old pattern, and no sequence is left incomplete.
TEST_CASE("switching patterns during a continuous scan never mixes patterns") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("switch");
  const std::string config_path = sl::test::writeTestConfig(ns, /*publish_maps=*/true);
  sl::test::DaemonProcess daemon(config_path);
  REQUIRE(daemon.started());

  sl::dds::Participant participant(0);
  sl::dds::Topic<sl_msgs_msg_dds__ProjectorMaps_> topic(participant, "rt/" + ns + "/projector_maps",
                                                  sl_msgs_msg_dds__ProjectorMaps__desc);
  sl::dds::Reader<sl_msgs_msg_dds__ProjectorMaps_> reader(participant, topic,
                                                    sl::dds::Qos().reliable().keepLast(8));
  const auto client_owner = connect(ns, /*points=*/false);
  sl::client::SensorClient& client = *client_owner;
  REQUIRE(reader.waitForWriters(1, DDS_SECS(10) * kTimeScale));

  struct Sample {
    std::string pattern;
    double up_valid, vp_valid;  // fractions of pixels
    std::int64_t stamp_ns;
  };
  std::vector<Sample> samples;
  // Collects maps until `count` samples of `pattern` arrived (bounded).
  auto collect = [&](const std::string& pattern, int count) {
    int seen = 0;
    const auto deadline = std::chrono::steady_clock::now() + scaledBound(15s);
    while (seen < count && std::chrono::steady_clock::now() < deadline) {
      auto loan = reader.take(4);
      if (loan.empty()) {
        std::this_thread::sleep_for(10ms);
        continue;
      }
      for (std::size_t i = 0; i < loan.size(); ++i) {
        if (!loan.isValid(i)) continue;
        const auto& m = loan[i];
        std::size_t up = 0, vp = 0;
        for (std::uint32_t k = 0; k < m.up._length; ++k) up += std::isfinite(m.up._buffer[k]);
        for (std::uint32_t k = 0; k < m.vp._length; ++k) vp += std::isfinite(m.vp._buffer[k]);
        const double n = double(m.width) * m.height;
        samples.push_back({m.pattern, up / n, vp / n, m.header.stamp.sec * 1'000'000'000LL + m.header.stamp.nanosec});
        seen += samples.back().pattern == pattern;
      }
    }
    return seen >= count;
  };

  auto reply = client.request(Command::kStart, "3+3_horizontal", 0, scaledBound(5s));
  REQUIRE(reply);
  REQUIRE(reply->accepted);
  CHECK(collect("3+3_horizontal", 2));
  const auto incomplete_before = client.status(scaledBound(3s))->sets_incomplete;
  // When each switch was requested, and how many samples preceded it.
  std::vector<std::pair<std::int64_t, std::size_t>> switches;
  switches.emplace_back(sl::test::nowNs(), samples.size());
  reply = client.request(Command::kSetPattern, "3+3_both", 0, scaledBound(5s));
  REQUIRE(reply);
  CHECK(reply->accepted);
  CHECK(collect("3+3_both", 2));
  switches.emplace_back(sl::test::nowNs(), samples.size());
  reply = client.request(Command::kSetPattern, "3+3_horizontal", 0, scaledBound(5s));
  REQUIRE(reply);
  CHECK(reply->accepted);
  std::size_t before_last = samples.size();
  CHECK(collect("3+3_horizontal", 2));
  reply = client.request(Command::kStop, "", 0, scaledBound(5s));
  REQUIRE(reply);
  CHECK(reply->accepted);
  const auto status = client.status(scaledBound(3s));
  REQUIRE(status);

  // The sequence running at each switch request completed with the old
  // pattern: its sample (stamped with its first trigger) is less than one
  // sequence period (frame count x image interval) older than the request. Frames or sets dropped by a
  // full queue (a loaded machine) would excuse a miss, so the checks hold
  // when none were. In a sanitizer build a frame that came after its set was
  // given up (unmatched) excuses it too: under TSan on a loaded machine the
  // simulated camera falls behind by seconds. Not in a release build, where
  // an unmatched frame at a switch is what this case is looking for.
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(config_path);
  const bool nothing_lost = status->frames_overflow == 0 && status->sets_overflow == 0 &&
                            (sl::test::kTimeScale == 1 || status->frames_unmatched == 0);
  for (const auto& [requested_ns, index] : switches) {
    REQUIRE(index >= 1);
    std::size_t last = index - 1;  // the last sample of the old pattern
    while (last + 1 < samples.size() && samples[last + 1].pattern == samples[index - 1].pattern)
      ++last;
    const std::int64_t last_old = samples[last].stamp_ns;
    const std::int64_t period_ns = config.findPattern(samples[last].pattern)->frameCount() *
                                   config.synchroniser.image_interval_ns;
    INFO("switch requested " << (requested_ns - last_old) * 1e-6
                             << " ms after the last old-pattern sequence began");
    // Not in a sanitizer build: there the simulated camera's timing, which
    // this bound is about, is not the sensor's (under TSan alongside other
    // work it skipped whole sequences and ran seconds late: 2.8 s against a
    // 2 s period); the pattern order and the no-mixing checks below still run.
    if (nothing_lost && kTimeScale == 1) CHECK(requested_ns - last_old < period_ns);
  }
  INFO("frames dropped " << status->frames_overflow << " (queue), " << status->frames_unmatched
                          << " (unmatched); sets dropped " << status->sets_overflow << " (queue)");
  if (nothing_lost) CHECK(status->sets_incomplete == incomplete_before);

  // Patterns appear in the requested order: h+, both+, h+.
  std::vector<std::string> runs;
  for (const auto& s : samples)
    if (runs.empty() || runs.back() != s.pattern) runs.push_back(s.pattern);
  CHECK(runs == std::vector<std::string>{"3+3_horizontal", "3+3_both", "3+3_horizontal"});
  CHECK(samples.size() > before_last);
  for (const auto& s : samples) {
    INFO(s.pattern << ": up valid " << s.up_valid << ", vp valid " << s.vp_valid);
    CHECK(s.up_valid > 0.8);
    if (s.pattern == "3+3_horizontal") {
      CHECK(s.vp_valid == 0.0);
    } else {
      CHECK(s.vp_valid > 0.8);
    }
  }
  const auto exit_status = daemon.terminate(5s);
  REQUIRE(exit_status);
  CHECK(*exit_status == 0);
}

// Recording and replay (issue 8): three scans recorded from the simulated
// sensor, then played back by a second daemon with `sensor: replay`, give
// bit-identical clouds.
TEST_CASE("a recording replayed through the daemon gives identical clouds") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("record");
  const std::string root = "/tmp/sl_test_recordings_" + ns;
  std::filesystem::remove_all(root);

  // 1. Record three scans on the simulated sensor.
  YAML::Node live = sl::test::simConfig(ns);
  live["runtime"]["recording_root"] = root;
  const std::string live_path = sl::test::writeConfigFile(live, ns + "_live");
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(live_path);
  std::vector<sl::pipeline::PointCloud> recorded;
  {
    sl::test::DaemonProcess daemon(live_path);
    REQUIRE(daemon.started());
    const auto client_owner = connect(ns);
    sl::client::SensorClient& client = *client_owner;
    const auto t0 = sl::test::nowNs();
    auto reply = client.request(Command::kStart, "3+3_horizontal", 3, scaledBound(5s), "../escape");
    REQUIRE(reply);
    CHECK(reply->code == sl::client::CommandResult::Code::kInvalidCommand);
    reply = client.request(Command::kStart, "3+3_horizontal", 3, scaledBound(5s), "rec1");
    REQUIRE(reply);
    REQUIRE(reply->accepted);
    for (int i = 0; i < 3; ++i) {
      auto cloud = client.receiveCloud(t0, scaledBound(10s));
      REQUIRE(cloud);
      recorded.push_back(std::move(*cloud));
    }
    // The recorder writes on its own thread: wait (bounded) for all three.
    std::uint64_t sets_recorded = 0;
    for (int i = 0; i < 50 * kTimeScale && sets_recorded < 3; ++i) {
      if (const auto s = client.status(scaledBound(2s))) sets_recorded = s->sets_recorded;
    }
    CHECK(sets_recorded == 3);
    REQUIRE(daemon.terminate(5s) == 0);
  }
  REQUIRE(sl::drivers::listRecordedSets(root + "/rec1").size() == 3);

  // 2. Replay them with the same calibration and patterns.
  const std::string calibration_path = "/tmp/sl_test_" + ns + "_calibration.yaml";
  sl::files::CalibrationFile calibration;
  calibration.calibration = config.calibration;
  sl::files::saveCalibration(calibration, calibration_path);
  YAML::Node replay = YAML::Clone(live);
  replay.remove("sim");
  replay["sensor"] = "replay";
  replay["calibration"] = calibration_path;
  replay["replay"]["dir"] = root + "/rec1";
  replay["replay"]["loop"] = false;
  const std::string replay_path = sl::test::writeConfigFile(replay, ns + "_replay");
  {
    sl::test::DaemonProcess daemon(replay_path);
    REQUIRE(daemon.started());
    const auto client_owner = connect(ns);
    sl::client::SensorClient& client = *client_owner;
    const auto t0 = startScans(client, "3+3_horizontal", 3);
    for (int i = 0; i < 3; ++i) {
      const auto cloud = client.receiveCloud(t0, scaledBound(10s));
      REQUIRE(cloud);
      REQUIRE(cloud->points.size() == recorded[i].points.size());
      std::size_t differing = 0;
      for (std::size_t k = 0; k < cloud->points.size(); ++k) {
        const auto& a = cloud->points[k];
        const auto& b = recorded[i].points[k];
        // Bitwise (NaN == NaN): the replayed images are the recorded ones.
        differing += std::memcmp(&a, &b, sizeof a) != 0;
      }
      INFO("scan " << i + 1);
      CHECK(differing == 0);
      CHECK(cloud->validCount() > 1'000'000);
    }
    REQUIRE(daemon.terminate(5s) == 0);
  }
  std::filesystem::remove_all(root);
}

// MCAP replay (issue 18): `sl_view record` writes the image sets a daemon on
// the simulated sensor publishes (dds.publish_image_sets) into an MCAP file;
// a second daemon with `sensor: replay` and `replay.file` plays the file and
// publishes the first daemon's clouds bit for bit.
TEST_CASE("image sets recorded as MCAP by sl_view replay through the daemon into identical clouds") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("mcap");
  const std::string mcap = "/tmp/sl_test_" + ns + ".mcap";
  YAML::Node live = sl::test::simConfig(ns);
  live["dds"]["publish_image_sets"] = true;
  const std::string live_path = sl::test::writeConfigFile(live, ns + "_live");
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(live_path);
  constexpr int kScans = 3;
  std::vector<sl::pipeline::PointCloud> published;
  {
    sl::test::DaemonProcess daemon(live_path);
    REQUIRE(daemon.started());
    const auto client_owner = connect(ns);
    const std::int64_t t0 = sl::test::nowNs();
    // sl_view record asks for the scans itself once its readers match.
    const std::string record = std::string(SL_BINARY_DIR) + "/tools/sl_view/sl_view record " + mcap +
                               " --ns " + ns + " --topics /" + ns + "/points,/" + ns +
                               "/image_sets --scan " + std::to_string(kScans) + " > /tmp/sl_test_" +
                               ns + "_record.log 2>&1";
    auto recorder = std::async(std::launch::async, [&] { return std::system(record.c_str()); });
    for (int i = 0; i < kScans; ++i) {
      auto cloud = client_owner->receiveCloud(t0, scaledBound(30s));
      REQUIRE(cloud);
      published.push_back(std::move(*cloud));
    }
    REQUIRE(recorder.wait_for(scaledBound(60s)) == std::future_status::ready);
    const int rc = recorder.get();
    INFO("sl_view record log: /tmp/sl_test_" << ns << "_record.log");
    REQUIRE(rc == 0);
    REQUIRE(daemon.terminate(5s) == 0);
  }
  REQUIRE(sl::drivers::RecordingReader::open(mcap)->size() == kScans);

  const std::string calibration_path = "/tmp/sl_test_" + ns + "_calibration.yaml";
  sl::files::CalibrationFile calibration;
  calibration.calibration = config.calibration;
  sl::files::saveCalibration(calibration, calibration_path);
  YAML::Node replay = YAML::Clone(live);
  replay.remove("sim");
  replay["sensor"] = "replay";
  replay["calibration"] = calibration_path;
  replay["dds"]["publish_image_sets"] = false;
  replay["replay"]["file"] = mcap;
  replay["replay"]["loop"] = false;
  const std::string replay_path = sl::test::writeConfigFile(replay, ns + "_replay");
  {
    sl::test::DaemonProcess daemon(replay_path);
    REQUIRE(daemon.started());
    const auto client_owner = connect(ns);
    const auto t0 = startScans(*client_owner, "3+3_horizontal", kScans);
    for (int i = 0; i < kScans; ++i) {
      INFO("scan " << i + 1);
      const auto cloud = client_owner->receiveCloud(t0, scaledBound(20s));
      REQUIRE(cloud);
      REQUIRE(cloud->points.size() == published[i].points.size());
      std::size_t differing = 0;
      for (std::size_t k = 0; k < cloud->points.size(); ++k)
        differing += std::memcmp(&cloud->points[k], &published[i].points[k], sizeof cloud->points[k]) != 0;
      CHECK(differing == 0);  // NaN bits included
      CHECK(cloud->validCount() > 1'000'000);
    }
    REQUIRE(daemon.terminate(5s) == 0);
  }
  // The same file given as `dir:` is named as the mistake it is.
  replay["replay"].remove("file");
  replay["replay"]["dir"] = mcap;
  const std::string wrong_key = sl::test::writeConfigFile(replay, ns + "_wrong_key");
  CHECK_THROWS_WITH(sl::daemon::loadConfig(wrong_key),
                    Catch::Contains("replay.dir") && Catch::Contains("given as file:"));
  std::filesystem::remove(mcap);
  std::filesystem::remove(calibration_path);
  std::filesystem::remove("/tmp/sl_test_" + ns + "_record.log");
}

// Motion compensation switched on for a static scene: the registration finds
// (almost) no shift and the clouds keep the accuracy of the uncompensated
// pipeline (same noise-model bounds, slightly wider for the resampling).
TEST_CASE("motion compensation on a static scene keeps the accuracy") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("motion");
  YAML::Node root = sl::test::simConfig(ns);
  root["motion_compensation"]["enabled"] = true;
  root["motion_compensation"]["axis"] = "y";  // along the fringes' direction of no change
  const std::string path = sl::test::writeConfigFile(root, ns);
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(path);
  REQUIRE(config.motion.enabled);

  sl::test::DaemonProcess daemon(path);
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns);
  sl::client::SensorClient& client = *client_owner;
  const auto t0 = startScans(client, "3+3_horizontal", 2);
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  for (int i = 0; i < 2; ++i) {
    const auto cloud = client.receiveCloud(t0, scaledBound(10s));
    REQUIRE(cloud);
    const PlaneStats s = comparePlane(*cloud, config, sim->groundTruth());
    WARN("motion compensation on, static scene, scan " << i + 1 << ": rms " << s.rms_error_mm
         << " mm (predicted " << s.predicted_rms_mm << "), bias " << s.mean_error_mm);
    CHECK(s.rms_error_mm < 1.2 * s.predicted_rms_mm);
    CHECK(std::abs(s.mean_error_mm) < 0.05);
    CHECK(s.outliers < 0.001 * (s.points + s.outliers));
  }
  const auto status = client.status(scaledBound(3s));
  REQUIRE(status);
  // A textureless scene gives the registration little to hold on to: an
  // implausible shift may be flagged (and ignored, or replaced by the
  // sequence's motion), but nothing else fails.
  INFO("last error: " << status->last_error);
  CHECK((status->last_error.empty() ||
         status->last_error.find("beyond max_shift_px") != std::string::npos ||
         status->last_error.find("disagreed with the sequence's motion") != std::string::npos));
  REQUIRE(daemon.terminate(5s) == 0);
}

// Depth and shading images and camera_info (ROS 2 types) for image tools.
TEST_CASE("depth and shading images and camera_info accompany each cloud") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("images");
  YAML::Node root = sl::test::simConfig(ns);
  root["dds"]["publish_images"] = true;
  const std::string path = sl::test::writeConfigFile(root, ns);
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(path);
  sl::test::DaemonProcess daemon(path);
  REQUIRE(daemon.started());

  sl::dds::Participant participant(0);
  using Image = sensor_msgs_msg_dds__Image_;
  using Info = sensor_msgs_msg_dds__CameraInfo_;
  sl::dds::Topic<Image> depth_topic(participant, "rt/" + ns + "/depth/image",
                                    sensor_msgs_msg_dds__Image__desc);
  sl::dds::Topic<Image> shading_topic(participant, "rt/" + ns + "/shading/image",
                                      sensor_msgs_msg_dds__Image__desc);
  sl::dds::Topic<Info> info_topic(participant, "rt/" + ns + "/camera_info",
                                  sensor_msgs_msg_dds__CameraInfo__desc);
  const auto qos = sl::dds::Qos().reliable().keepLast(4);
  sl::dds::Reader<Image> depth_reader(participant, depth_topic, qos);
  sl::dds::Reader<Image> shading_reader(participant, shading_topic, qos);
  sl::dds::Reader<Info> info_reader(participant, info_topic, qos);
  const auto client_owner = connect(ns);
  sl::client::SensorClient& client = *client_owner;
  REQUIRE(depth_reader.waitForWriters(1, DDS_SECS(10) * kTimeScale));
  REQUIRE(shading_reader.waitForWriters(1, DDS_SECS(10) * kTimeScale));
  REQUIRE(info_reader.waitForWriters(1, DDS_SECS(10) * kTimeScale));

  const auto t0 = startScans(client, "3+3_horizontal", 1);
  const auto cloud = client.receiveCloud(t0, scaledBound(10s));
  REQUIRE(cloud);
  auto takeOne = [](auto& reader) {
    for (int i = 0; i < 500 * kTimeScale; ++i) {
      auto loan = reader.take(1);
      if (!loan.empty() && loan.isValid(0)) return loan;
      std::this_thread::sleep_for(10ms);
    }
    return decltype(reader.take(1)){};
  };
  auto depth = takeOne(depth_reader);
  auto shading = takeOne(shading_reader);
  auto info = takeOne(info_reader);
  REQUIRE(!depth.empty());
  REQUIRE(!shading.empty());
  REQUIRE(!info.empty());

  const Image& d = depth[0];
  CHECK(std::string(d.encoding) == "32FC1");
  CHECK(d.width == 1440);
  CHECK(d.height == 1080);
  CHECK(d.step == 1440 * 4);
  CHECK(std::string(d.header.frame_id) == cloud->frame_id);
  REQUIRE(d.data._length == 1440u * 1080u * 4u);
  std::size_t mismatches = 0, valid = 0;
  for (std::size_t i = 0; i < cloud->points.size(); ++i) {
    float z;
    std::memcpy(&z, d.data._buffer + 4 * i, 4);
    const float expected = cloud->points[i].z;  // mm
    if (std::isnan(expected)) {
      mismatches += !std::isnan(z);
    } else {
      ++valid;
      mismatches += !(std::abs(z * 1000.0f - expected) < 1e-3f);
    }
  }
  CHECK(mismatches == 0);
  CHECK(valid > 1'000'000);
  const Image& s = shading[0];
  CHECK(std::string(s.encoding) == "mono8");
  CHECK(s.data._length == 1440u * 1080u);
  const Info& ci = info[0];
  CHECK(std::string(ci.distortion_model) == "plumb_bob");
  REQUIRE(ci.d._length == 5);
  CHECK(ci.d._buffer[0] == config.calibration.camera.distortion[0]);
  CHECK(ci.k[0] == config.calibration.camera.fx);
  CHECK(ci.k[2] == config.calibration.camera.cx);
  CHECK(ci.k[4] == config.calibration.camera.fy);
  CHECK(ci.p[10] == 1.0);
  CHECK(ci.width == 1440);
  REQUIRE(daemon.terminate(5s) == 0);
}

// SIGHUP reloads the run-time settings; anything else is refused with a
// message on the status topic, and the daemon keeps running.
TEST_CASE("SIGHUP applies run-time settings and refuses the rest") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("reload");
  YAML::Node root = sl::test::simConfig(ns);
  const std::string path = sl::test::writeConfigFile(root, ns);
  sl::test::DaemonProcess daemon(path);
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns);
  sl::client::SensorClient& client = *client_owner;
  auto scanValid = [&] {
    const auto t0 = sl::test::nowNs();
    REQUIRE(client.request(Command::kStart, "", 1, scaledBound(5s))->accepted);
    const auto cloud = client.receiveCloud(t0, scaledBound(10s));
    REQUIRE(cloud);
    return cloud->validCount();
  };
  auto lastError = [&] {
    std::string error;
    for (int i = 0; i < 30 * kTimeScale && error.empty(); ++i)
      if (const auto s = client.status(scaledBound(1s))) error = s->last_error;
    return error;
  };
  const std::size_t before = scanValid();
  CHECK(before > 1'000'000);

  // A decoder threshold no pixel passes: applied without a restart.
  root["decoder"]["min_modulation"] = 250;
  std::ofstream(path) << root;
  daemon.signal(SIGHUP);
  std::this_thread::sleep_for(scaledBound(500ms));
  CHECK(scanValid() < before / 100);

  // A change that needs a restart: refused, named, nothing applied.
  root["decoder"]["min_modulation"] = 8;
  root["sim"]["seed"] = 2;
  std::ofstream(path) << root;
  daemon.signal(SIGHUP);
  const std::string refused = lastError();
  CHECK(refused.find("config reload rejected: 'sim'") != std::string::npos);
  CHECK(scanValid() < before / 100);  // the threshold of the refused file was not applied

  // A file that does not load: refused with the loader's message.
  std::ofstream(path) << "sensor: [unclosed\n";
  daemon.signal(SIGHUP);
  std::string failed;
  for (int i = 0; i < 30 * kTimeScale && failed.find("reload failed") == std::string::npos; ++i)
    if (const auto s = client.status(scaledBound(1s))) failed = s->last_error;
  CHECK(failed.find("config reload failed") != std::string::npos);

  // A later good reload clears that error (it no longer holds).
  root["sim"]["seed"] = 1;
  std::ofstream(path) << root;
  daemon.signal(SIGHUP);
  std::optional<sl::client::StatusInfo> after;
  for (int i = 0; i < 30 * kTimeScale && (!after || !after->last_error.empty()); ++i) {
    std::this_thread::sleep_for(100ms);
    after = client.status(scaledBound(1s));
  }
  REQUIRE(after);
  CHECK(after->last_error.empty());
  CHECK(after->last_error_ns == 0);
  CHECK(after->errors_reported >= 2);  // the refused and the failed reload, still counted
  REQUIRE(daemon.terminate(5s) == 0);
}

// Requests that Cyclone cannot deserialize (a string without its terminating
// NUL, from a look-alike type without type information) never reach the daemon's
// reader; they are counted in requests_malformed, and a good request is
// still answered.
TEST_CASE("requests that fail to deserialize are counted, not lost without a trace") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("malformed");
  YAML::Node root = sl::test::simConfig(ns);
  root["dds"]["requests"]["max_string"] = 100;  // dds.requests: the limits are the config's
  const std::string path = sl::test::writeConfigFile(root, ns);
  sl::test::DaemonProcess daemon(path);
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns);
  sl::client::SensorClient& client = *client_owner;
  const auto before = client.status(scaledBound(5s));
  REQUIRE(before);
  CHECK(before->requests_malformed == 0);
  const std::string writer = std::string(SL_BINARY_DIR) + "/tests/malformed_writer " + ns + " 7";
  REQUIRE(std::system(writer.c_str()) == 0);
  std::optional<sl::client::StatusInfo> s;
  for (int i = 0; i < 50 * kTimeScale && (!s || s->requests_malformed < 7); ++i) {
    std::this_thread::sleep_for(100ms);
    s = client.status(scaledBound(1s));
  }
  REQUIRE(s);
  CHECK(s->requests_malformed == 7);
  CHECK(s->requests_received == before->requests_received);  // none was taken
  const auto reply = client.request(Command::kListPatterns, "", 0, scaledBound(5s));
  REQUIRE(reply);
  CHECK(reply->accepted);
  REQUIRE(client.clientId().size() <= 100);
  const auto refused =
      client.request(Command::kSetPattern, std::string(101, 'p'), 0, scaledBound(5s));
  REQUIRE(refused);
  CHECK(refused->code == sl::client::CommandResult::Code::kInvalidOption);
  CHECK(refused->reason.find("pattern is 101 bytes, more than 100") != std::string::npos);
  REQUIRE(daemon.terminate(5s) == 0);
}

namespace {

// The reader GUID a points_subscriber writes to `path` once matched (up to
// 10 s x kTimeScale); empty if none came.
std::string guidFromFile(const std::string& path) {
  std::string guid;
  for (int i = 0; i < 200 * kTimeScale && guid.empty(); ++i) {
    std::ifstream(path) >> guid;
    if (guid.empty()) std::this_thread::sleep_for(50ms);
  }
  return guid;
}

}  // namespace

// A reader that stops acknowledging (here a keep-all reader whose history of
// one cloud is full and that never takes: Cyclone then refuses further
// clouds and does not acknowledge them) loses every cloud pushed out of the
// daemon's keep-last history before it acknowledged it; the status lists
// each matched reader of the points topic, says which one stopped
// acknowledging and counts its lost clouds. A reader that reads shows 0.
// Each subscriber has its own process (tests/daemon/points_subscriber.c).
TEST_CASE("a points reader that stops acknowledging is listed with its lost clouds") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("unacked");
  // The small rig of the request fuzzer: 64 x 48 clouds at 5 Hz.
  YAML::Node root = YAML::LoadFile(sl::test::sourcePath("fuzz/data/request_daemon.yaml"));
  root["dds"]["namespace"] = ns;
  sl::test::DaemonProcess daemon(sl::test::writeConfigFile(root, ns));
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns, /*points=*/false);
  sl::client::SensorClient& client = *client_owner;

  const std::string subscriber = std::string(SL_BINARY_DIR) + "/tests/points_subscriber";
  const std::string reading_file = "/tmp/sl_test_" + ns + "_reading",
                    stuck_file = "/tmp/sl_test_" + ns + "_stuck";
  std::filesystem::remove(reading_file);
  std::filesystem::remove(stuck_file);
  sl::test::ChildProcess reading({subscriber, ns, "read", reading_file});
  sl::test::ChildProcess stuck({subscriber, ns, "stuck", stuck_file});
  const std::string reading_guid = guidFromFile(reading_file), stuck_guid = guidFromFile(stuck_file);
  REQUIRE_FALSE(reading_guid.empty());
  REQUIRE_FALSE(stuck_guid.empty());

  REQUIRE(client.request(Command::kStart, "", 0, scaledBound(5s))->accepted);
  std::optional<sl::client::StatusInfo> s;
  sl::client::PointsReaderInfo of_reading, of_stuck;  // as listed in s
  bool listed_reading = false, listed_stuck = false;
  const auto deadline = std::chrono::steady_clock::now() + scaledBound(30s);
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(200ms);
    s = client.status(scaledBound(1s));
    if (!s) continue;
    listed_reading = listed_stuck = false;
    for (const auto& r : s->points_readers) {
      if (r.guid == reading_guid) of_reading = r, listed_reading = true;
      if (r.guid == stuck_guid) of_stuck = r, listed_stuck = true;
    }
    if (listed_stuck && of_stuck.clouds_lost >= 10 && s->scans_done >= 20) break;
  }
  REQUIRE(s);
  REQUIRE(listed_reading);
  REQUIRE(listed_stuck);
  CHECK(of_stuck.reliable);
  CHECK_FALSE(of_stuck.acknowledging);
  CHECK(of_stuck.clouds_lost >= 10);
  // It got the first cloud only; all others but the last 4 (the writer's
  // history, which it may yet get) are lost to it, give or take the one or
  // two clouds published between the status's counts.
  CHECK(of_stuck.clouds_lost <= s->scans_done);
  CHECK(of_stuck.clouds_lost + 1 + 4 + 2 >= s->scans_done);
  CHECK(of_reading.reliable);
  CHECK(of_reading.acknowledging);
  CHECK(of_reading.clouds_lost == 0);
  CHECK(s->clouds_lost_to_readers >= of_stuck.clouds_lost);
  REQUIRE(client.request(Command::kStop, "", 0, scaledBound(5s))->accepted);
  REQUIRE(daemon.terminate(5s) == 0);
}

// A reader whose process stops for longer than its participant's lease is
// unmatched by the daemon and matched again, with the same GUID, when it
// resumes; the clouds written meanwhile never reach it. The status must list
// it again with every cloud it missed (published minus taken), not restart
// its count at 0, and the total must include them. The subscriber's lease is
// 2 s (x kTimeScale) and it is stopped for three leases.
TEST_CASE("a points reader away longer than its lease keeps its count of lost clouds") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("lease");
  YAML::Node root = YAML::LoadFile(sl::test::sourcePath("fuzz/data/request_daemon.yaml"));
  root["dds"]["namespace"] = ns;
  sl::test::DaemonProcess daemon(sl::test::writeConfigFile(root, ns));
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns, /*points=*/false);
  sl::client::SensorClient& client = *client_owner;

  const std::string subscriber = std::string(SL_BINARY_DIR) + "/tests/points_subscriber";
  const std::string guid_file = "/tmp/sl_test_" + ns + "_guid",
                    taken_file = "/tmp/sl_test_" + ns + "_taken";
  std::filesystem::remove(guid_file);
  std::filesystem::remove(taken_file);
  const auto lease = std::chrono::seconds(2 * kTimeScale);
  const std::string dds_uri = std::getenv("CYCLONEDDS_URI");
  setenv("CYCLONEDDS_URI",
         (dds_uri + ",<Discovery><LeaseDuration>" + std::to_string(lease.count()) +
          "s</LeaseDuration></Discovery>")
             .c_str(),
         1);
  sl::test::ChildProcess reader({subscriber, ns, "read", guid_file, taken_file});
  setenv("CYCLONEDDS_URI", dds_uri.c_str(), 1);
  const std::string guid = guidFromFile(guid_file);
  REQUIRE_FALSE(guid.empty());

  auto listed = [&](const sl::client::StatusInfo& st) -> std::optional<sl::client::PointsReaderInfo> {
    for (const auto& r : st.points_readers)
      if (r.guid == guid) return r;
    return std::nullopt;
  };
  REQUIRE(client.request(Command::kStart, "", 0, scaledBound(5s))->accepted);
  std::this_thread::sleep_for(2s);
  reader.signal(SIGSTOP);
  // Unmatched once its lease has passed.
  bool unlisted = false;
  const auto away_until = std::chrono::steady_clock::now() + 3 * lease;
  while (std::chrono::steady_clock::now() < away_until) {
    std::this_thread::sleep_for(200ms);
    if (const auto st = client.status(scaledBound(1s)); st && !listed(*st)) unlisted = true;
  }
  reader.signal(SIGCONT);
  CHECK(unlisted);
  // Matched again and taking clouds.
  std::optional<sl::client::PointsReaderInfo> back;
  const auto deadline = std::chrono::steady_clock::now() + scaledBound(20s);
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(200ms);
    const auto st = client.status(scaledBound(1s));
    if (st && (back = listed(*st)) && back->acknowledging) break;
  }
  REQUIRE(back);
  std::this_thread::sleep_for(1s);
  REQUIRE(client.request(Command::kStop, "", 0, scaledBound(5s))->accepted);
  std::this_thread::sleep_for(1s * kTimeScale);  // the last clouds reach the reader
  const auto st = client.status(scaledBound(1s));
  REQUIRE(st);
  back = listed(*st);
  REQUIRE(back);
  unsigned long long taken = 0;
  std::ifstream(taken_file) >> taken;
  REQUIRE(taken > 0);
  REQUIRE(st->scans_done >= taken);
  const std::uint64_t missed = st->scans_done - taken;
  INFO("published " << st->scans_done << ", taken " << taken << ", reported lost "
                    << back->clouds_lost << ", total " << st->clouds_lost_to_readers);
  // Three leases at 5 Hz: clouds were missed, and every one is counted, give
  // or take the writer's history of 4 (which the reader may have got just
  // before it stopped or been counted as losing) and one in flight. In a
  // sanitizer build the slowed reader's acknowledgements can lag by more
  // than the history (reader_acks.h): up to a few more are counted.
  CHECK(missed >= 5);
  CHECK(back->clouds_lost + 5 >= missed);
  CHECK(back->clouds_lost <= missed + 5 * kTimeScale);
  CHECK(st->clouds_lost_to_readers >= back->clouds_lost);
  REQUIRE(daemon.terminate(5s) == 0);
  std::filesystem::remove(guid_file);
  std::filesystem::remove(taken_file);
}

// Two cameras (issue 7): the horizontal pattern is triangulated by the camera
// beside the projector, the vertical one by the camera above it, switched
// with the pattern during a continuous scan. The image sets come from a
// recording of two simulated rigs (each camera with its own projector pose
// and the scene placed alike in front of it), played back with
// `sensor: replay`, so every cloud can be checked against its camera's
// ground truth.
TEST_CASE("two cameras: each pattern is triangulated by its camera, switched with the pattern") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("twocam");
  const std::string dir = "/tmp/sl_test_" + ns + "_recording";
  std::filesystem::remove_all(dir);

  YAML::Node root = sl::test::simConfig(ns);
  YAML::Node patterns = YAML::Load(
      "[{name: 3+3_horizontal, family: phase_shift_3+3, direction: horizontal, fringes: 16,"
      "  cameras: [sim_top]},"
      " {name: 3+3_vertical, family: phase_shift_3+3, direction: vertical, fringes: 16,"
      "  cameras: [left]}]");
  root["patterns"] = patterns;
  // The simulated rig of the first camera (a sim sensor has no camera
  // "left": its config lists no pattern cameras, which load checks).
  YAML::Node rig = YAML::Clone(root);
  for (auto pattern : rig["patterns"]) pattern.remove("cameras");
  const sl::daemon::DaemonConfig top = sl::daemon::loadConfig(sl::test::writeConfigFile(rig, ns + "_top"));
  // The "left" rig: projector 150 mm below the camera, turned up by 15.25 deg.
  sl::daemon::DaemonConfig left = top;
  left.sim.camera_id = "left";
  left.sim.rig.R = Eigen::AngleAxisd(-15.25 * M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix();
  left.sim.rig.t = -left.sim.rig.R * Eigen::Vector3d(0, 150, 0);
  left.calibration = left.sim.rig;
  left.patterns = {top.patterns.at(1)};  // comparePlane reads the encoded pattern from [0]
  const auto sim_top = sl::drivers::SimulatedSensor::create(top.sim);
  const auto sim_left = sl::drivers::SimulatedSensor::create(left.sim);

  // Record sets h, v, h, v with both cameras' frames.
  sl::drivers::createRecording(dir, "two simulated rigs");
  const std::int64_t base = sl::test::nowNs();
  const char* order[] = {"3+3_horizontal", "3+3_vertical", "3+3_horizontal", "3+3_vertical"};
  for (int k = 0; k < 4; ++k) {
    sl::pipeline::ImageSet set;
    set.sequence_id = k;
    set.pattern_name = order[k];
    set.trigger_stamp_ns = base + k * 200'000'000LL;
    for (const auto* sim : {sim_top.get(), sim_left.get()}) {
      sl::pipeline::CameraImages images;
      images.camera_id = sim->config().camera_id;
      for (int i = 0; i < 6; ++i) {
        images.frames.push_back(sim->render(order[k], i, 1000 + 10 * k + i));
        images.stamps_ns.push_back(set.trigger_stamp_ns + i * 33'333'333LL);
      }
      set.cameras.push_back(images);
    }
    sl::drivers::writeRecordedSet(dir, k + 1, set);
  }
  const std::string calibration_top = "/tmp/sl_test_" + ns + "_top_calibration.yaml";
  const std::string calibration_left = "/tmp/sl_test_" + ns + "_left_calibration.yaml";
  sl::files::CalibrationFile file;
  file.calibration = top.sim.rig;
  sl::files::saveCalibration(file, calibration_top);
  file.calibration = left.sim.rig;
  sl::files::saveCalibration(file, calibration_left);

  YAML::Node replay = YAML::Clone(root);
  replay.remove("sim");
  replay["sensor"] = "replay";
  replay["replay"]["dir"] = dir;
  replay["calibration"] = calibration_top;
  replay["calibrations"]["left"] = calibration_left;
  sl::test::DaemonProcess daemon(sl::test::writeConfigFile(replay, ns + "_replay"));
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns);
  sl::client::SensorClient& client = *client_owner;

  // Two clouds per phase, each checked against the ground truth of the camera
  // that must have triangulated it.
  auto phase = [&](const std::string& pattern, bool switch_pattern) {
    const std::int64_t since = sl::test::nowNs();
    const auto reply = switch_pattern
                           ? client.request(Command::kSetPattern, pattern, 0, scaledBound(5s))
                           : client.request(Command::kStart, pattern, 0, scaledBound(5s));
    REQUIRE(reply);
    REQUIRE(reply->accepted);
    const bool vertical = pattern == "3+3_vertical";
    for (int i = 0; i < 2; ++i) {
      const auto cloud = client.receiveCloud(since, scaledBound(10s));
      if (!cloud) {
        const auto status = client.status(scaledBound(1s));
        REQUIRE(status);
        FAIL("no " << pattern << " cloud " << i + 1 << " within 10 s; status: scans "
                   << status->scans_done << ", frames/s " << status->frame_rate_hz
                   << ", frames overflow " << status->frames_overflow << ", unmatched "
                   << status->frames_unmatched << ", sets overflow " << status->sets_overflow
                   << ", incomplete " << status->sets_incomplete << ", last error '"
                   << status->last_error << "'");
      }
      INFO(pattern << " cloud " << i + 1 << " frame " << cloud->frame_id);
      CHECK(cloud->frame_id == (vertical ? "left_optical_frame" : top.dds.frame_id));
      const PlaneStats s = vertical ? comparePlane(*cloud, left, sim_left->groundTruth(), true)
                                    : comparePlane(*cloud, top, sim_top->groundTruth());
      INFO("rms " << s.rms_error_mm << " mm, predicted " << s.predicted_rms_mm);
      CHECK(s.rms_error_mm < 1.1 * s.predicted_rms_mm);
      CHECK(std::abs(s.mean_error_mm) < 0.05);
    }
  };
  phase("3+3_horizontal", false);
  phase("3+3_vertical", true);
  phase("3+3_horizontal", true);
  REQUIRE(client.request(Command::kStop, "", 0, scaledBound(5s))->accepted);
  REQUIRE(daemon.terminate(5s) == 0);
  std::filesystem::remove_all(dir);
}

// Software trigger (issue 7): without trigger times from a board the daemon
// steps the projector pattern by pattern and grabs each image itself. The
// clouds keep the accuracy of the hardware-triggered ones; the scans come at
// the lower rate that settle + exposure per pattern allow.
TEST_CASE("software-triggered scans match the ground truth at the lower rate") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("swtrigger");
  const std::string config_path = sl::test::writeTestConfig(ns);
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(config_path);
  sl::test::DaemonProcess daemon(config_path);
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns);
  sl::client::SensorClient& client = *client_owner;

  sl::client::StartRequest request;
  request.pattern = "3+3_horizontal";
  request.count = 3;
  request.trigger = sl::client::TriggerMode::kSoftware;
  request.cameras = {"sim_top"};
  request.motion_compensation = false;
  const auto t0 = sl::test::nowNs();
  const auto reply = client.start(request, scaledBound(5s));
  REQUIRE(reply);
  REQUIRE(reply->accepted);

  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  std::vector<std::int64_t> stamps;
  for (int i = 0; i < 3; ++i) {
    const auto cloud = client.receiveCloud(t0, scaledBound(10s));
    REQUIRE(cloud);
    stamps.push_back(cloud->stamp_ns);
    const PlaneStats s = comparePlane(*cloud, config, sim->groundTruth());
    WARN("software trigger, scan " << i + 1 << ": rms " << s.rms_error_mm << " mm (predicted "
         << s.predicted_rms_mm << "), bias " << s.mean_error_mm << " mm, outliers "
         << s.outliers);
    CHECK(s.rms_error_mm < 1.1 * s.predicted_rms_mm);
    CHECK(s.rms_error_mm > 0.9 * s.predicted_rms_mm);
    CHECK(std::abs(s.mean_error_mm) < 0.05);
    CHECK(s.outliers < 0.001 * (s.points + s.outliers));
  }
  // Each pattern costs at least the settle time plus the simulated camera's
  // exposure and readout (one frame interval): sequences start at least
  // 6 * (10 + 33.3) ms apart,
  // against 6 * 33.3 ms with the trigger board.
  const double min_period_s =
      6 * (config.software_trigger.settle_s + config.synchroniser.image_interval_ns * 1e-9);
  for (std::size_t i = 1; i < stamps.size(); ++i) {
    const double period_s = (stamps[i] - stamps[i - 1]) * 1e-9;
    WARN("software trigger: sequence period " << period_s << " s (>= " << min_period_s
         << " s; hardware trigger: " << 6 * config.synchroniser.image_interval_ns * 1e-9 << " s)");
    CHECK(period_s >= min_period_s);
    CHECK(period_s < 4 * kTimeScale * min_period_s);  // and not stalled
  }
  const auto status = client.status(scaledBound(3s));
  REQUIRE(status);
  CHECK(status->trigger == sl::client::TriggerMode::kSoftware);
  CHECK(status->cameras == std::vector<std::string>{"sim_top"});
  CHECK(status->sets_incomplete == 0);

  // Options travel over DDS and are validated there too.
  request.cameras = {"left"};
  auto rejected = client.start(request, scaledBound(5s));
  REQUIRE(rejected);
  CHECK(rejected->code == sl::client::CommandResult::Code::kInvalidOption);
  CHECK(rejected->reason.find("unknown camera 'left'") != std::string::npos);
  REQUIRE(daemon.terminate(5s) == 0);
}

// A second camera colours the cloud (issue 7): the pattern is triangulated by
// sim_top and takes its intensity from sim_left, 100 mm to its left with a
// parallel axis, both calibrated against the one projector. Checked against
// the simulator's truth: a point sim_left cannot see has no intensity; a point
// it sees has the mean of sim_left's rendered frames at the pixel where the
// simulator's ground truth puts that surface point.
TEST_CASE("a second camera gives the cloud its intensity") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("colour");
  YAML::Node root = sl::test::simConfig(ns);
  const Eigen::Vector3d left_offset(100, 0, 0);  // X_left = X_top + offset (mm)
  {
    const sl::daemon::DaemonConfig plain =
        sl::daemon::loadConfig(sl::test::writeConfigFile(root, ns + "_plain"));
    const Eigen::Vector3d t_left = plain.sim.rig.t - plain.sim.rig.R * left_offset;
    YAML::Node second;
    second["camera_id"] = "sim_left";
    second["calibration"] = YAML::Clone(root["sim"]["rig"]["calibration"]);
    second["calibration"]["projector_pose"]["translation_mm"] =
        std::vector<double>{t_left.x(), t_left.y(), t_left.z()};
    root["sim"]["second_camera"] = second;
    root["patterns"][0]["intensity_camera"] = "sim_left";
  }
  const std::string path = sl::test::writeConfigFile(root, ns);
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(path);
  REQUIRE(config.pattern_intensity_camera.at("3+3_horizontal") == "sim_left");
  sl::test::DaemonProcess daemon(path);
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns);
  const auto t0 = startScans(*client_owner, "3+3_horizontal", 1);
  const auto cloud = client_owner->receiveCloud(t0, scaledBound(10s));
  REQUIRE(cloud);
  REQUIRE(daemon.terminate(5s) == 0);

  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  const sl::pipeline::PinholeModel& left = config.sim.second_camera->rig.camera;
  // 1. Visibility: inside sim_left's image (2 px margin) -> an intensity,
  // outside -> NaN.
  std::size_t inside = 0, outside = 0, wrong = 0;
  for (const auto& p : cloud->points) {
    if (!std::isfinite(p.z)) continue;
    const Eigen::Vector2d uv = left.project(Eigen::Vector3d(p.x, p.y, p.z) + left_offset);
    const bool in = uv.x() > 2 && uv.y() > 2 && uv.x() < left.width - 3 && uv.y() < left.height - 3;
    const bool out = uv.x() < -2 || uv.y() < -2 || uv.x() > left.width + 1 || uv.y() > left.height + 1;
    if (in) ++inside, wrong += !std::isfinite(p.intensity);
    if (out) ++outside, wrong += std::isfinite(p.intensity);
  }
  INFO("points seen by sim_left " << inside << ", not seen " << outside << ", wrong " << wrong);
  CHECK(inside > 500'000);
  CHECK(outside > 100'000);
  CHECK(wrong == 0);

  // 2. Values: sim_left's mean image at its pixel (u, v) against the cloud
  // point at the pixel where sim_top sees the same surface point.
  cv::Mat mean = cv::Mat::zeros(left.height, left.width, CV_32FC1), frame;
  for (int i = 0; i < 6; ++i) {
    sim->render(1, "3+3_horizontal", i, 500 + i).convertTo(frame, CV_32F);
    mean += frame / 6.0;
  }
  const sl::drivers::SimGroundTruth truth = sim->groundTruthAt(1, 0);
  const sl::pipeline::PinholeModel& top = config.sim.rig.camera;
  std::vector<double> errors;
  for (int v = 0; v < left.height; v += 3) {
    for (int u = 0; u < left.width; u += 3) {
      const cv::Vec3f x = truth.xyz_mm.at<cv::Vec3f>(v, u);
      if (!std::isfinite(x[2])) continue;
      const Eigen::Vector2d rc = top.project(Eigen::Vector3d(x[0], x[1], x[2]) - left_offset);
      const int c = int(std::lround(rc.x())), r = int(std::lround(rc.y()));
      if (c < 0 || r < 0 || c >= cloud->width || r >= cloud->height) continue;
      const auto& p = cloud->points[std::size_t(r) * cloud->width + c];
      if (!std::isfinite(p.z) || !std::isfinite(p.intensity)) continue;
      // The same surface point (not one hidden behind it).
      if ((Eigen::Vector3d(p.x, p.y, p.z) + left_offset -
           Eigen::Vector3d(x[0], x[1], x[2])).norm() > 2.0)
        continue;
      errors.push_back(std::abs(p.intensity - mean.at<float>(v, u)));
    }
  }
  REQUIRE(errors.size() > 50'000);
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2], p95 = errors[errors.size() * 95 / 100];
  WARN("intensity from sim_left: " << errors.size() << " points, |error| median " << median
       << " DN, 95th percentile " << p95 << " DN");
  // Measured: median 0.25 DN, 95th percentile 0.72 DN (noise of two
  // independent 6-frame means, interpolation across 1 px).
  CHECK(median < 0.6);
  CHECK(p95 < 2.0);
}

// dds.publish_image_sets: every synchronized image set on rt/<ns>/image_sets,
// with its stamps, pattern and camera ids; decoding a received set with the
// offline pipeline (ScanProcessor, as sl_process does) gives the daemon's
// cloud bit for bit.
namespace {
std::int64_t stampNs(const builtin_interfaces_msg_dds__Time_& t) {
  return std::int64_t(t.sec) * 1'000'000'000 + t.nanosec;
}
}  // namespace

TEST_CASE("image sets published by the daemon decode offline to its clouds, bit for bit") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("sets");
  YAML::Node root = sl::test::simConfig(ns);
  root["dds"]["publish_image_sets"] = true;
  const std::string path = sl::test::writeConfigFile(root, ns);
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(path);
  sl::test::DaemonProcess daemon(path);
  REQUIRE(daemon.started());

  using SetMsg = sl_msgs_msg_dds__ImageSet_;
  using CloudMsg = sensor_msgs_msg_dds__PointCloud2_;
  sl::dds::Participant participant(0);
  sl::dds::Topic<SetMsg> sets_topic(participant, "rt/" + ns + "/image_sets",
                                    sl_msgs_msg_dds__ImageSet__desc);
  sl::dds::Topic<CloudMsg> points_topic(participant, "rt/" + ns + "/points",
                                        sensor_msgs_msg_dds__PointCloud2__desc);
  sl::dds::Reader<SetMsg> sets_reader(participant, sets_topic, sl::dds::Qos().reliable().keepLast(4));
  sl::dds::Reader<CloudMsg> points_reader(participant, points_topic,
                                          sl::dds::Qos().reliable().keepLast(4));
  const auto client_owner = connect(ns, false);
  REQUIRE(sets_reader.waitForWriters(1, DDS_SECS(10) * kTimeScale));
  REQUIRE(points_reader.waitForWriters(1, DDS_SECS(10) * kTimeScale));
  constexpr std::size_t kScans = 2;
  startScans(*client_owner, "3+3_horizontal", 0);  // continuous: a lost sequence is no failure

  // The offline pipeline with the daemon's configuration, triangulating in
  // metres as the daemon does (ScanEngine's CloudUnit::kMetres).
  const sl::pipeline::PatternSpec& pattern = *config.findPattern("3+3_horizontal");
  const sl::pipeline::Decoder decoder(pattern, config.decoder);
  sl::pipeline::TriangulatorOptions in_metres = config.triangulator;
  in_metres.min_depth_mm *= 1e-3f;
  in_metres.max_depth_mm *= 1e-3f;
  const sl::pipeline::Triangulator triangulator(sl::pipeline::inUnits(config.calibration, 1e-3),
                                                in_metres);
  sl::pipeline::ScanProcessor processor(2);
  // Sets and clouds are only taken and kept (the newest kKept of each) while
  // the daemon runs; the sets are decoded after the stop. Decoding each set
  // as it came fell behind the daemon in a TSan build (a set takes seconds
  // there), so the loop taking them never ended, and the readers' histories
  // had long dropped the clouds to compare with.
  constexpr std::size_t kKept = 6;
  std::map<sl::pipeline::TimestampNs, sl::pipeline::CameraImages> sets;
  std::map<sl::pipeline::TimestampNs, std::vector<std::uint8_t>> received;
  auto keep = [](auto& by_stamp) {
    if (by_stamp.size() > kKept) by_stamp.erase(by_stamp.begin());
  };
  auto matched = [&] {
    std::size_t n = 0;
    for (const auto& entry : sets) n += received.count(entry.first);
    return n;
  };
  const auto deadline = std::chrono::steady_clock::now() + scaledBound(20s);
  while (matched() < kScans && std::chrono::steady_clock::now() < deadline) {
    for (auto loan = sets_reader.take(1); !loan.empty(); loan = sets_reader.take(1)) {
      if (!loan.isValid(0)) continue;
      const SetMsg& m = loan[0];
      REQUIRE(std::string(m.pattern) == "3+3_horizontal");
      REQUIRE(m.camera_count == 1);
      REQUIRE(m.camera_ids._length == 1);
      CHECK(std::string(m.camera_ids._buffer[0]) == config.sim.camera_id);
      REQUIRE(m.bit_depths._length == 1);
      REQUIRE(m.images._length == static_cast<std::uint32_t>(pattern.frameCount()));
      sl::pipeline::CameraImages images;
      images.camera_id = m.camera_ids._buffer[0];
      images.bit_depth = m.bit_depths._buffer[0];
      const auto stamp = stampNs(m.header.stamp);
      for (std::uint32_t i = 0; i < m.images._length; ++i) {
        const sensor_msgs_msg_dds__Image_& im = m.images._buffer[i];
        REQUIRE(std::string(im.encoding) == "mono8");
        REQUIRE(im.data._length == im.step * im.height);
        CHECK(std::string(im.header.frame_id) == config.dds.frame_id);
        const auto t = stampNs(im.header.stamp);
        // Frame i is exposed i image intervals after the trigger.
        CHECK(std::llabs(t - stamp - i * config.synchroniser.image_interval_ns) < 1000);
        images.frames.push_back(
            cv::Mat(int(im.height), int(im.width), CV_8UC1, im.data._buffer, im.step).clone());
        images.stamps_ns.push_back(t);
      }
      sets[stamp] = std::move(images);
      keep(sets);
    }
    for (auto loan = points_reader.take(1); !loan.empty(); loan = points_reader.take(1)) {
      if (!loan.isValid(0)) continue;
      const CloudMsg& c = loan[0];
      received[stampNs(c.header.stamp)].assign(c.data._buffer, c.data._buffer + c.data._length);
      keep(received);
    }
    std::this_thread::sleep_for(20ms);
  }
  const auto status = client_owner->status(scaledBound(2s));
  INFO("sets kept " << sets.size() << ", clouds kept " << received.size() << ", writes timed out "
                    << (status ? status->writes_timed_out : 0));
  REQUIRE(client_owner->request(Command::kStop, "", 0, scaledBound(5s)));
  REQUIRE(matched() >= kScans);
  std::size_t compared = 0;
  for (const auto& [stamp, images] : sets) {
    if (received.count(stamp) == 0) continue;  // its cloud was not kept, or came after the stop
    INFO("set stamped " << stamp);
    auto [maps, cloud] = processor.process(decoder.codec(), triangulator, images, stamp,
                                           config.dds.frame_id,
                                           sl::pipeline::ScanProcessor::Keep::kCloud);
    std::vector<float> metres;  // as published
    for (const auto& p : cloud->points) metres.insert(metres.end(), {p.x, p.y, p.z, p.intensity});
    const std::vector<std::uint8_t>& bytes = received.at(stamp);
    REQUIRE(bytes.size() == metres.size() * sizeof(float));
    CHECK(std::memcmp(bytes.data(), metres.data(), bytes.size()) == 0);  // NaN bits included
    ++compared;
  }
  CHECK(compared >= kScans);
  REQUIRE(daemon.terminate(5s) == 0);
}

// Per-point quality on rt/<ns>/points (dds.points_normals,
// dds.points_confidence): the fields as PCL names them, unit normals towards
// the camera matching the simulated plane's, and a confidence (expected
// depth sigma) that predicts the measured depth error per band of sigma
// within 20 % (docs/metrology.md "Per-point quality").
TEST_CASE("points with normals and confidence: fields, unit normals, calibrated sigma", "[quality]") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("quality");
  YAML::Node root = sl::test::simConfig(ns);
  root["dds"]["points_normals"] = true;
  root["dds"]["points_confidence"] = true;
  const std::string path = sl::test::writeConfigFile(root, ns);
  const sl::daemon::DaemonConfig config = sl::daemon::loadConfig(path);
  REQUIRE(config.camera_noise);  // the simulator's radiometry
  sl::test::DaemonProcess daemon(path);
  REQUIRE(daemon.started());

  using CloudMsg = sensor_msgs_msg_dds__PointCloud2_;
  sl::dds::Participant participant(0);
  sl::dds::Topic<CloudMsg> points_topic(participant, "rt/" + ns + "/points",
                                        sensor_msgs_msg_dds__PointCloud2__desc);
  sl::dds::Reader<CloudMsg> points_reader(participant, points_topic,
                                          sl::dds::Qos().reliable().keepLast(4));
  const auto client_owner = connect(ns, false);
  REQUIRE(points_reader.waitForWriters(1, DDS_SECS(10) * kTimeScale));
  constexpr int kScans = 2;
  const std::int64_t t0 = startScans(*client_owner, "3+3_horizontal", kScans);

  const std::vector<std::string> names = {"x",        "y",        "z",        "intensity",
                                          "normal_x", "normal_y", "normal_z", "confidence"};
  std::vector<std::vector<float>> clouds;  // 8 floats a point, as received
  const auto deadline = std::chrono::steady_clock::now() + scaledBound(20s);
  while (clouds.size() < kScans && std::chrono::steady_clock::now() < deadline) {
    for (auto loan = points_reader.take(1); !loan.empty(); loan = points_reader.take(1)) {
      if (!loan.isValid(0)) continue;
      const CloudMsg& c = loan[0];
      if (stampNs(c.header.stamp) < t0) continue;
      REQUIRE(c.width == 1440);
      REQUIRE(c.height == 1080);
      REQUIRE(c.fields._length == names.size());
      for (std::uint32_t i = 0; i < c.fields._length; ++i) {
        CHECK(std::string(c.fields._buffer[i].name) == names[i]);
        CHECK(c.fields._buffer[i].offset == 4 * i);
        CHECK(c.fields._buffer[i].datatype == 7);  // FLOAT32
        CHECK(c.fields._buffer[i].count == 1);
      }
      REQUIRE(c.point_step == 32);
      REQUIRE(c.row_step == 32 * c.width);
      REQUIRE(c.data._length == std::size_t(32) * c.width * c.height);
      CHECK_FALSE(c.is_bigendian);
      std::vector<float> values(c.data._length / 4);
      std::memcpy(values.data(), c.data._buffer, c.data._length);
      clouds.push_back(std::move(values));
    }
    std::this_thread::sleep_for(20ms);
  }
  REQUIRE(clouds.size() == kScans);

  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  const sl::drivers::SimGroundTruth& gt = sim->groundTruth();
  const sl::drivers::SimPlane& plane = config.sim.scene.planes.at(0);
  const Eigen::Vector3d plane_normal = plane.normal.normalized();
  struct Sample {
    double sigma_mm, error_mm;
  };
  std::vector<Sample> samples;
  std::vector<double> angles_deg, tilt_sigma_deg;
  Eigen::Vector3d mean_normal = Eigen::Vector3d::Zero(), truth_normal = Eigen::Vector3d::Zero();
  const double fx = config.calibration.camera.fx;
  std::size_t valid = 0, with_confidence = 0, with_normal = 0, not_unit = 0, away = 0;
  for (const auto& cloud : clouds) {
    for (int r = 0; r < 1080; ++r) {
      for (int c = 0; c < 1440; ++c) {
        const float* p = cloud.data() + 8 * (std::size_t(r) * 1440 + c);
        const cv::Vec3f g = gt.xyz_mm.at<cv::Vec3f>(r, c);
        if (!std::isfinite(p[2])) {
          CHECK(std::isnan(p[7]));  // no point, no confidence
          continue;
        }
        if (!std::isfinite(g[2])) continue;
        const Eigen::Vector3d x_gt(g[0], g[1], g[2]);
        if (std::abs(plane_normal.dot(x_gt - plane.point)) > 1e-3) continue;  // not on the plane
        ++valid;
        const Eigen::Vector3d x(p[0], p[1], p[2]);  // metres
        const Eigen::Vector3d n(p[4], p[5], p[6]);
        if (n.allFinite()) {
          ++with_normal;
          if (std::abs(n.norm() - 1) > 1e-4) ++not_unit;
          if (n.dot(x) >= 0) ++away;
          // The plane's normal oriented towards the camera.
          const Eigen::Vector3d truth = plane_normal.dot(x_gt) < 0 ? plane_normal : -plane_normal;
          angles_deg.push_back(std::acos(std::clamp(n.normalized().dot(truth), -1.0, 1.0)) * 180 / M_PI);
          mean_normal += n;
          truth_normal = truth;
          // docs/metrology.md: the normal's tilt noise per axis is about
          // sqrt(2) sigma_z / (2 step footprint), footprint = z / f.
          if (std::isfinite(p[7]))
            tilt_sigma_deg.push_back(std::sqrt(2.0) * p[7] /
                                     (2 * config.dds.points_normal_step * p[2] / fx) * 180 / M_PI);
        }
        if (std::isfinite(p[7])) {
          ++with_confidence;
          CHECK(p[7] > 0);
          const double error_mm = p[2] * 1e3 - g[2];
          const double sigma_mm = p[7] * 1e3;
          if (std::abs(error_mm) > 10 * sigma_mm) continue;  // wrong fringe order: no noise
          samples.push_back({sigma_mm, error_mm});
        }
      }
    }
  }
  INFO("plane points " << valid << ", with confidence " << with_confidence << ", with normal "
                       << with_normal);
  REQUIRE(valid > 500000);
  CHECK(with_confidence > 0.99 * valid);
  CHECK(with_normal > 0.95 * valid);
  CHECK(not_unit == 0);
  CHECK(away == 0);
  std::nth_element(angles_deg.begin(), angles_deg.begin() + angles_deg.size() / 2, angles_deg.end());
  const double median_angle = angles_deg[angles_deg.size() / 2];
  std::nth_element(tilt_sigma_deg.begin(), tilt_sigma_deg.begin() + tilt_sigma_deg.size() / 2,
                   tilt_sigma_deg.end());
  // The angle of a tilt with two Gaussian components of this sigma has the
  // median sqrt(2 ln 2) sigma.
  const double predicted_median = std::sqrt(2 * std::log(2.0)) * tilt_sigma_deg[tilt_sigma_deg.size() / 2];
  const double mean_off_deg =
      std::acos(std::clamp(mean_normal.normalized().dot(truth_normal), -1.0, 1.0)) * 180 / M_PI;
  WARN("normals on the simulated plane (step " << config.dds.points_normal_step
       << " px): median angle to the truth " << median_angle << " deg (noise model: "
       << predicted_median << "), mean normal off by " << mean_off_deg << " deg");
  CHECK(mean_off_deg < 0.5);  // no bias beyond a fraction of a degree
  CHECK(median_angle < 2 * predicted_median);
  CHECK(median_angle > 0.5 * predicted_median);

  // Bands of predicted sigma (quantiles), each: RMS measured error against
  // RMS predicted sigma.
  REQUIRE(samples.size() > 0.99 * with_confidence);
  std::sort(samples.begin(), samples.end(),
            [](const Sample& a, const Sample& b) { return a.sigma_mm < b.sigma_mm; });
  constexpr int kBands = 4;
  for (int b = 0; b < kBands; ++b) {
    const std::size_t lo = samples.size() * b / kBands, hi = samples.size() * (b + 1) / kBands;
    double sum_sigma2 = 0, sum_error2 = 0;
    for (std::size_t i = lo; i < hi; ++i) {
      sum_sigma2 += samples[i].sigma_mm * samples[i].sigma_mm;
      sum_error2 += samples[i].error_mm * samples[i].error_mm;
    }
    const double predicted = std::sqrt(sum_sigma2 / (hi - lo)), measured = std::sqrt(sum_error2 / (hi - lo));
    WARN("band " << b << ": sigma " << samples[lo].sigma_mm << "-" << samples[hi - 1].sigma_mm
                 << " mm, predicted RMS " << predicted << " mm, measured RMS " << measured
                 << " mm, ratio " << measured / predicted);
    CHECK(measured / predicted > 0.8);
    CHECK(measured / predicted < 1.2);
  }
  REQUIRE(client_owner->request(Command::kStop, "", 0, scaledBound(5s)));
  REQUIRE(daemon.terminate(5s) == 0);
  std::filesystem::remove(path);
}

// The keys of the per-point quality (docs/formats.md): the simulator's noise
// by default, camera_noise overriding it, patterns without a noise model
// refused at load.
TEST_CASE("points_confidence: camera noise from the simulator or camera_noise, phase patterns only",
          "[quality]") {
  YAML::Node root = sl::test::simConfig("quality_keys");
  root["dds"]["points_confidence"] = true;
  root["sim"]["radiometry"]["analog_gain"] = 2.0;
  auto parse = [](const YAML::Node& n) {
    YAML::Emitter out;
    out << n;
    return sl::daemon::parseConfig(out.c_str(), "quality.yaml");
  };
  {
    const sl::daemon::DaemonConfig c = parse(root);
    REQUIRE(c.camera_noise);
    CHECK(c.camera_noise->gain_dn_per_electron == Approx(2 * c.sim.gain_dn_per_electron));
    CHECK(c.camera_noise->read_noise_dn == Approx(2 * c.sim.read_noise_dn));
    CHECK(c.dds.points_layout.confidence);
    CHECK_FALSE(c.dds.points_layout.normals);
  }
  root["camera_noise"]["gain_dn_per_electron"] = 0.02;
  root["camera_noise"]["read_noise_dn"] = 0.7;
  {
    const sl::daemon::DaemonConfig c = parse(root);
    REQUIRE(c.camera_noise);
    CHECK(c.camera_noise->gain_dn_per_electron == 0.02);
    CHECK(c.camera_noise->read_noise_dn == 0.7);
  }
  root["camera_noise"]["read_noise_dn"] = -1;
  CHECK_THROWS_WITH(parse(root), Catch::Contains("camera_noise.read_noise_dn"));
  root.remove("camera_noise");
  YAML::Node gray;
  gray["name"] = "gray";
  gray["family"] = "gray_code";
  gray["direction"] = "horizontal";
  root["patterns"].push_back(gray);
  CHECK_THROWS_WITH(parse(root), Catch::Contains("pattern 'gray' has no phase-noise model"));
  root["dds"]["points_confidence"] = false;
  CHECK_NOTHROW(parse(root));  // normals and plain clouds need no noise model
  root["dds"]["points_normal_step"] = 0;
  CHECK_THROWS_WITH(parse(root), Catch::Contains("points_normal_step"));
}

// Adaptive scanning (issue 33 item 4): a robot's velocity published as
// geometry_msgs/TwistStamped steers a continuous scan: at rest the static
// mode's pattern, linear motion along x the compensated pattern, a rotation
// pauses with the reason, and once the velocity stops coming the safe mode
// (here static) takes over, each switch counted.
TEST_CASE("adaptive scanning follows a stop-go-turn velocity and falls back when it goes stale",
          "[adaptive]") {
  sl::test::useLoopbackDds();
  const std::string ns = sl::test::uniqueNamespace("adaptive");
  YAML::Node root = sl::test::simConfig(ns);
  YAML::Node adaptive;
  adaptive["velocity_topic"] = "/" + ns + "/velocity";
  adaptive["velocity_timeout_s"] = 0.5 * kTimeScale;
  adaptive["min_dwell_s"] = 0.3;
  adaptive["safe_mode"] = "static";
  adaptive["modes"]["static"]["pattern"] = "3+3_both";
  adaptive["modes"]["linear_x"]["pattern"] = "3+3_horizontal";
  adaptive["modes"]["linear_x"]["motion_compensation"] = true;  // motion_compensation.axis: x (default)
  adaptive["modes"]["linear_y"]["pattern"] = "3+3_both";
  adaptive["modes"]["moving"]["pause"] = true;
  root["adaptive"] = adaptive;
  sl::test::DaemonProcess daemon(sl::test::writeConfigFile(root, ns));
  REQUIRE(daemon.started());
  const auto client_owner = connect(ns, /*points=*/false);
  sl::client::SensorClient& client = *client_owner;

  // The robot: publishes the current velocity at 20 Hz until told to stop.
  sl::dds::Participant participant(0);
  sl::dds::Topic<geometry_msgs_msg_dds__TwistStamped_> topic(participant, "rt/" + ns + "/velocity",
                                                             geometry_msgs_msg_dds__TwistStamped__desc);
  sl::dds::Writer<geometry_msgs_msg_dds__TwistStamped_> writer(participant, topic,
                                                               sl::dds::Qos().reliable().keepLast(10));
  std::mutex robot_mutex;
  geometry_msgs_msg_dds__TwistStamped_ velocity{};
  velocity.header.frame_id = const_cast<char*>("sl_camera_optical_frame");
  std::atomic<bool> publishing{true};
  std::thread robot([&] {
    while (publishing) {
      {
        std::lock_guard lock(robot_mutex);
        const std::int64_t now = sl::test::nowNs();
        velocity.header.stamp.sec = static_cast<std::int32_t>(now / 1'000'000'000);
        velocity.header.stamp.nanosec = static_cast<std::uint32_t>(now % 1'000'000'000);
        writer.write(velocity);
      }
      std::this_thread::sleep_for(50ms);
    }
  });
  auto setVelocity = [&](double vx, double vy, double wz) {
    std::lock_guard lock(robot_mutex);
    velocity.twist.linear.x = vx;
    velocity.twist.linear.y = vy;
    velocity.twist.angular.z = wz;
  };
  struct StopRobot {
    std::atomic<bool>& publishing;
    std::thread& robot;
    ~StopRobot() {
      publishing = false;
      if (robot.joinable()) robot.join();
    }
  } stop_robot{publishing, robot};
  REQUIRE(writer.waitForReaders(1, DDS_SECS(10) * kTimeScale));

  // Every status seen, for the order of the modes.
  std::vector<std::string> modes;
  auto waitFor = [&](auto done) {
    return sl::test::statusWhen(
        client,
        [&](const sl::client::StatusInfo& s) {
          if (modes.empty() || modes.back() != s.adaptive_mode) modes.push_back(s.adaptive_mode);
          return done(s);
        },
        scaledBound(20s));
  };

  setVelocity(0, 0, 0);
  auto reply = client.request(Command::kStart, "3+3_horizontal", 0, scaledBound(5s));
  REQUIRE(reply);
  REQUIRE(reply->accepted);

  // At rest: static's pattern, no compensation, scans published.
  auto s = waitFor([](const auto& s) {
    return s.adaptive_mode == "static" && s.pattern == "3+3_both" && s.scans_done >= 2;
  });
  REQUIRE(s);
  INFO("mode " << s->adaptive_mode << " (" << s->adaptive_reason << "), pattern " << s->pattern);
  CHECK(s->adaptive_mode == "static");
  CHECK(s->pattern == "3+3_both");
  CHECK_FALSE(s->motion_compensation);
  const std::uint64_t switches_static = s->adaptive_switches;
  CHECK(switches_static >= 1);

  // Linear motion along x at 50 mm/s: the compensated pattern.
  setVelocity(0.05, 0.002, 0);
  s = waitFor([](const auto& s) {
    return s.adaptive_mode == "linear_x" && s.pattern == "3+3_horizontal" && s.motion_compensation;
  });
  REQUIRE(s);
  INFO("mode " << s->adaptive_mode << " (" << s->adaptive_reason << "), pattern " << s->pattern);
  CHECK(s->adaptive_mode == "linear_x");
  CHECK(s->adaptive_reason.find("linear along x") != std::string::npos);
  CHECK(s->pattern == "3+3_horizontal");
  CHECK(s->motion_compensation);
  CHECK(s->adaptive_switches > switches_static);
  const std::uint64_t scans_linear = s->scans_done;
  s = waitFor([&](const auto& s) { return s.scans_done >= scans_linear + 2; });
  REQUIRE(s);
  CHECK(s->scans_done >= scans_linear + 2);  // clouds of the compensated pattern

  // Turning: paused, the reason in the status.
  setVelocity(0.02, 0, 0.3);
  s = waitFor([](const auto& s) {
    return s.adaptive_mode == "moving" && s.state == sl::client::ScanState::kDegraded;
  });
  REQUIRE(s);
  INFO("mode " << s->adaptive_mode << " (" << s->adaptive_reason << "), degraded: " << s->degraded_reason);
  CHECK(s->adaptive_mode == "moving");
  CHECK(s->adaptive_reason.find("rotating") != std::string::npos);
  CHECK(s->state == sl::client::ScanState::kDegraded);
  CHECK(s->degraded_reason.find("paused by adaptive scanning (moving: rotating") != std::string::npos);
  // While paused, only sets already in flight become scans.
  const std::uint64_t scans_paused = s->scans_done;
  std::this_thread::sleep_for(scaledBound(1500ms));
  s = client.status(scaledBound(3s));
  REQUIRE(s);
  CHECK(s->adaptive_mode == "moving");
  CHECK(s->scans_done <= scans_paused + 4);  // queue_depth sets + results + one in processing

  // The robot stops publishing: after velocity_timeout_s the safe mode
  // (static), scanning again, the staleness as the reason.
  publishing = false;
  robot.join();
  s = waitFor([](const auto& s) {
    return s.adaptive_mode == "static" && s.pattern == "3+3_both" &&
           s.state == sl::client::ScanState::kScanning;
  });
  REQUIRE(s);
  INFO("mode " << s->adaptive_mode << " (" << s->adaptive_reason << "), state "
               << static_cast<int>(s->state) << ": " << s->degraded_reason);
  CHECK(s->adaptive_mode == "static");
  CHECK(s->adaptive_reason.find("velocity stale") != std::string::npos);
  CHECK(s->pattern == "3+3_both");
  CHECK(s->state == sl::client::ScanState::kScanning);
  const std::uint64_t scans_stale = s->scans_done;
  s = waitFor([&](const auto& s) { return s.scans_done >= scans_stale + 2; });
  REQUIRE(s);
  CHECK(s->scans_done >= scans_stale + 2);  // scanning resumed
  // static, linear_x, moving, static (more only if the velocity went stale
  // in between on a loaded machine).
  CHECK(s->adaptive_switches >= 4);
  std::vector<std::string> distinct;
  for (const auto& m : modes)
    if (!m.empty()) distinct.push_back(m);
  INFO("modes seen in order: " << [&] {
    std::string text;
    for (const auto& m : distinct) text += m + " ";
    return text;
  }());
  auto at = distinct.begin();
  for (const char* expected : {"static", "linear_x", "moving", "static"}) {
    at = std::find(at, distinct.end(), expected);
    CHECK(at != distinct.end());
    if (at != distinct.end()) ++at;
  }

  reply = client.request(Command::kStop, "", 0, scaledBound(5s));
  REQUIRE(reply);
  CHECK(reply->accepted);
  s = waitFor([](const auto& s) { return s.adaptive_mode.empty(); });
  REQUIRE(s);
  CHECK(s->adaptive_mode.empty());  // no continuous scan: no mode
  const auto exit_status = daemon.terminate(5s);
  REQUIRE(exit_status);
  CHECK(*exit_status == 0);
}
