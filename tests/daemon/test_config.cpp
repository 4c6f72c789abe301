// Config loading: the shipped config parses; every kind of mistake is one
// ConfigError naming the file, the line and the key.
#include <catch2/catch.hpp>
#include <limits>
#include <sys/stat.h>
#include <unistd.h>
#include <filesystem>

#include <fstream>
#include <regex>
#include <sstream>

#include "sl/files/calibration_io.h"
#include "sl/daemon/config.h"
#include "sl/dds/cloud_layout.h"
#include "sl/dds/environment.h"
#include "sl/daemon/log.h"
#include "sl/drivers/sim_rig.h"
#include "sl/pipeline/projector_response.h"
#include "support/config_text.h"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>

namespace {

std::string shippedConfig() { return sl::test::shippedSimConfigText(); }

// The shipped config with the first occurrence of `from` replaced by `to`.
std::string edited(const std::string& from, const std::string& to) {
  std::string text = shippedConfig();
  const auto at = text.find(from);
  REQUIRE(at != std::string::npos);
  return text.replace(at, from.size(), to);
}

std::string errorOf(const std::string& yaml) { return sl::test::configErrorOf(yaml); }

}  // namespace

TEST_CASE("the shipped sim config loads with the documented values") {
  const auto config = sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  CHECK(config.sensor == sl::daemon::SensorKind::kSim);
  CHECK(config.sim.rig.camera.width == 1440);
  CHECK(config.sim.rig.camera.height == 1080);
  CHECK(config.sim.rig.projector.width == 1824);
  CHECK(config.sim.rig.projector.height == 1140);
  CHECK(config.patterns.size() >= 2);
  CHECK(config.patterns[0].projector_width == 1824);
  CHECK(config.sim.patterns.size() == config.patterns.size());
  CHECK(config.findPattern(config.runtime.default_pattern) != nullptr);
  CHECK(config.dds.ns == "sl");
  CHECK(config.synchroniser.image_interval_ns == 33'333'333);
  CHECK(config.runtime.trigger == sl::client::TriggerMode::kHardware);
  CHECK(config.software_trigger.settle_s == 0.01);
  // The decoder section is DecoderOptions' defaults (sl_eval decodes with those).
  const sl::pipeline::DecoderOptions decoder_defaults;
  CHECK(config.decoder.min_modulation == decoder_defaults.min_modulation);  // auto
  CHECK(config.decoder.max_unwrap_error == decoder_defaults.max_unwrap_error);
  CHECK(config.decoder.reject_saturated == decoder_defaults.reject_saturated);
  // 'calibration: sim' = the rig's own geometry.
  CHECK(config.calibration.t.isApprox(config.sim.rig.t));
  CHECK(config.calibration.camera.fx == config.sim.rig.camera.fx);
  // The projector sits 150 mm to the side of the camera: centre C = -R^T t.
  CHECK((-config.calibration.R.transpose() * config.calibration.t).norm() ==
        Approx(150.0).margin(0.05));
}

TEST_CASE("the shipped sim config's rig is drivers::simRig(), the one the tests and sl_eval use") {
  const auto config = sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  const sl::pipeline::CameraProjectorCalibration rig = sl::drivers::simRig();
  for (const auto& [in_file, in_code] : {std::pair{config.sim.rig.camera, rig.camera},
                                         std::pair{config.sim.rig.projector, rig.projector}}) {
    CHECK(in_file.width == in_code.width);
    CHECK(in_file.height == in_code.height);
    CHECK(in_file.fx == in_code.fx);
    CHECK(in_file.fy == in_code.fy);
    CHECK(in_file.cx == in_code.cx);
    CHECK(in_file.cy == in_code.cy);
    CHECK(in_file.distortion == in_code.distortion);
  }
  CHECK(config.sim.rig.R.isApprox(rig.R, 1e-9));
  CHECK((config.sim.rig.t - rig.t).norm() < 0.01);  // mm; the file rounds to 10 um
}

TEST_CASE("the shipped sim config's camera noise model is SimConfig's default (sl_eval uses it)") {
  const auto config = sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  const sl::drivers::SimConfig defaults;
  CHECK(config.sim.projector_brightness_dn == defaults.projector_brightness_dn);
  CHECK(config.sim.reference_distance_mm == defaults.reference_distance_mm);
  CHECK(config.sim.ambient_dn == defaults.ambient_dn);
  CHECK(config.sim.gain_dn_per_electron == defaults.gain_dn_per_electron);
  CHECK(config.sim.read_noise_dn == defaults.read_noise_dn);
  CHECK(config.sim.bit_depth == defaults.bit_depth);
}

TEST_CASE("config mistakes are reported with file, line and key") {
  struct Case {
    std::string from, to, expected;
  };
  const auto c = GENERATE(
      Case{"  seed: 1", "  seed: 1\n  sed: 2", "test.yaml:10: unknown key 'sim.sed'"},
      Case{"camera_fps: 30", "camera_fps: fast",
           "key 'sim.camera_fps': expected a number, found 'fast'"},
      Case{"camera_fps: 30", "camera_fps: -3", "key 'sim.camera_fps': must be > 0"},
      Case{"bit_depth: 8", "bit_depth: 20", "key 'sim.bit_depth': must be in 8..16"},
      Case{"fx: 2400,", "fx: [1, 2],", "key 'sim.rig.calibration.camera.fx': expected a number, found a list"},
      Case{"distortion: [-0.08, 0.12, 0.0005, -0.0003, 0.0]", "distortion: [1, 2]",
           "key 'sim.rig.calibration.camera.distortion': expected 5 numbers"},
      Case{"direction: horizontal", "direction: diagonal",
           "key 'patterns[0].direction': direction must be horizontal, vertical or both"},
      Case{"fringes: 40}", "fringes: 1000}", "key 'patterns[0].fringes'"},
      Case{"family: phase_shift_3+3", "family: hexagons",
           "key 'patterns[0].family': unknown pattern family 'hexagons'"},
      Case{"default_pattern: 3+3_horizontal", "default_pattern: nope",
           "key 'runtime.default_pattern': no pattern named 'nope'"},
      Case{"sensor: sim", "sensor: lightcrafter", "key 'sensor': unknown sensor 'lightcrafter'"},
      Case{"calibration: sim", "calibration: /nonexistent/calib.yaml",
           "key 'calibration': cannot read calibration file '/nonexistent/calib.yaml'"},
      Case{"    - plane:", "    - cube:", "each scene item is exactly one of 'plane' or 'sphere'"},
      Case{"radius_mm: 60", "radius_mm: 0", "key 'sim.scene[1].sphere.radius_mm': must be > 0"},
      Case{"namespace: sl", "namespace: /bad/", "key 'dds.namespace'"},
      Case{"queue_depth: 2", "queue_depth: 0", "key 'runtime.queue_depth': must be in 1..64"},
      Case{"trigger: hardware", "trigger: manual",
           "key 'runtime.trigger': must be hardware or software, not 'manual'"},
      Case{"queue_depth: 2", "queue_depth: 2\n  stall_timeout_s: 0",
           "key 'runtime.stall_timeout_s': must be in [0.1, 3600] seconds"},
      Case{"queue_depth: 2", "queue_depth: 2\n  last_error_hold_s: -1",
           "key 'runtime.last_error_hold_s': must be in [0, 1e6] seconds"},
      Case{"queue_depth: 2", "queue_depth: 2\n  recording_max_mb: 1.5",
           "key 'runtime.recording_max_mb': must be a whole number in 0..1099511627776 (0 = no limit)"},
      Case{"queue_depth: 2", "queue_depth: 2\n  recording_min_free_mb: -3",
           "key 'runtime.recording_min_free_mb': must be a whole number"},
      Case{"settle_s: 0.01", "settle_s: -1", "key 'software_trigger.settle_s': must be in [0, 10]"},
      Case{"max_unwrap_error: 0.3", "max_unwrap_error: 0.7", "key 'decoder.max_unwrap_error'"},
      Case{"min_modulation: auto", "min_modulation: -3",
           "key 'decoder.min_modulation': must be >= 0"},
      Case{"min_modulation: auto", "min_modulation: bright", "key 'decoder.min_modulation'"},
      Case{"max_unwrap_error: 0.3", "max_unwrap_error: 0.3\n  projector_gamma: 0",
           "key 'decoder.projector_gamma': must be > 0"},
      Case{"max_unwrap_error: 0.3", "max_unwrap_error: 0.3\n  projector_gamma: bright",
           "key 'decoder.projector_gamma': expected a number"},
      Case{"max_unwrap_error: 0.3", "max_unwrap_error: 0.3\n  projector_response: [0, 0.6, 0.5, 1]",
           "key 'decoder.projector_response': "},
      Case{"max_unwrap_error: 0.3", "max_unwrap_error: 0.3\n  projector_response: [0.5]",
           "key 'decoder.projector_response': "},
      Case{"max_unwrap_error: 0.3",
           "max_unwrap_error: 0.3\n  projector_gamma: 2.2\n  projector_response: [0, 1]",
           "key 'decoder.projector_response': give one of projector_gamma and projector_response"},
      Case{"use: best", "use: diagonal", "key 'triangulator.use': must be best, columns or rows"},
      Case{"rotation_deg: [0, 15.25, 0],", "rotation_deg: [0, 15.25, 0], rotation: [1,0,0,0,1,0,0,0,1],",
           "give exactly one of 'rotation'"},
      Case{"status_period_s: 1.0", "status_period_s: 1.0\n  qos: {points: {reliability: maybe}}",
           "key 'dds.qos.points.reliability': must be reliable or best_effort, not 'maybe'"},
      Case{"status_period_s: 1.0", "status_period_s: 1.0\n  qos: {images: {depth: 0}}",
           "key 'dds.qos.images.depth': must be in 1..64"},
      Case{"status_period_s: 1.0", "status_period_s: 1.0\n  qos: {cloud: {depth: 1}}",
           "unknown key 'dds.qos.cloud'"},
      Case{"status_period_s: 1.0", "status_period_s: 1.0\n  requests: {max_string: 8}",
           "key 'dds.requests.max_string': must be in 16..65536"},
      Case{"status_period_s: 1.0", "status_period_s: 1.0\n  requests: {rate_hz: 0}",
           "key 'dds.requests.rate_hz': must be in [0.1, 10000] requests/s"},
      Case{"status_period_s: 1.0", "status_period_s: 1.0\n  requests: {limit: 3}",
           "unknown key 'dds.requests.limit'"},
      Case{"patterns:\n", "patterns: []\nunused:\n", "key 'patterns': expected a non-empty list"},
      // Limits checked before anything is allocated or created (issue 17).
      Case{"namespace: sl", "namespace: " + std::string(65600, 'n'),
           "key 'dds.namespace': must be 1..128 letters"},
      Case{"frame_id: sl_camera_optical_frame", "frame_id: " + std::string(300, 'f'),
           "key 'dds.frame_id': must be 1..128 characters"},
      Case{"projector:   {width: 1824, height: 1140,", "projector:   {width: 100000, height: 100000,",
           "key 'sim.rig.calibration.projector.width': must be 1..16384"},
      Case{"camera:      {width: 1440, height: 1080,", "camera:      {width: 1440, height: 2000000,",
           "key 'sim.rig.calibration.camera.height': must be 1..16384"},
      Case{"camera:      {width: 1440, height: 1080,", "camera:      {width: 16000, height: 16000,",
           "key 'sim.rig.calibration.camera.height': 16000 x 16000 is more than 50 megapixels"},
      Case{"  seed: 1", "  seed: 1\n  seed: 2", "test.yaml:10: key 'sim.seed' appears twice in the same map"},
      Case{"calibration: sim", "calibration: /tmp", "key 'calibration': cannot read calibration file '/tmp': a directory"},
      Case{"status_period_s: 1.0", "status_period_s: 1.0\n  points_decimation: 0",
           "key 'dds.points_decimation': must be 1..16"},
      Case{"calibration: sim", "calibration: /dev/null",
           "key 'calibration': cannot read calibration file '/dev/null': not a regular file"});
  INFO("edit: '" << c.from << "' -> '" << c.to << "'");
  const std::string message = errorOf(edited(c.from, c.to));
  INFO("message: " << message);
  CHECK(message.rfind("test.yaml", 0) == 0);  // names the file first
  CHECK(message.find(c.expected) != std::string::npos);
  CHECK(message.find('\n') == std::string::npos);  // one line
}

TEST_CASE("dds.qos sets each topic's writer QoS, the rest keep their defaults") {
  const auto c = sl::daemon::parseConfig(
      edited("status_period_s: 1.0",
             "status_period_s: 1.0\n  qos:\n    points: {reliability: best_effort, depth: 1}\n"
             "    image_sets: {depth: 3, max_blocking_s: 0.5}"),
      "test.yaml");
  CHECK_FALSE(c.dds.points_qos.reliable);
  CHECK(c.dds.points_qos.depth == 1);
  CHECK(c.dds.image_sets_qos.reliable);
  CHECK(c.dds.image_sets_qos.depth == 3);
  CHECK(c.dds.image_sets_qos.max_blocking_s == 0.5);
  CHECK(c.dds.images_qos.depth == sl::daemon::DdsConfig{}.images_qos.depth);
  const auto defaults = sl::daemon::parseConfig(shippedConfig(), "test.yaml");
  CHECK(defaults.dds.points_qos.reliable);
  CHECK(defaults.dds.points_qos.depth == sl::daemon::DdsConfig{}.points_qos.depth);
}

TEST_CASE("dds.points_zero_copy is on unless turned off, and only a boolean") {
  CHECK(sl::daemon::parseConfig(shippedConfig(), "test.yaml").dds.points_zero_copy);
  CHECK_FALSE(sl::daemon::parseConfig(
                  edited("status_period_s: 1.0", "status_period_s: 1.0\n  points_zero_copy: false"), "test.yaml")
                  .dds.points_zero_copy);
  const std::string message =
      errorOf(edited("status_period_s: 1.0", "status_period_s: 1.0\n  points_zero_copy: sometimes"));
  INFO(message);
  CHECK(message.find("dds.points_zero_copy") != std::string::npos);
}

TEST_CASE("dds.points_decimation and dds.points_valid_only shape the published cloud") {
  const auto c = sl::daemon::parseConfig(
      edited("status_period_s: 1.0", "status_period_s: 1.0\n  points_decimation: 3\n  points_valid_only: true"),
      "test.yaml");
  CHECK(c.dds.points_layout.decimation == 3);
  CHECK(c.dds.points_layout.valid_only);
  const auto defaults = sl::daemon::parseConfig(shippedConfig(), "test.yaml");
  CHECK(defaults.dds.points_layout.decimation == 1);
  CHECK_FALSE(defaults.dds.points_layout.valid_only);

  // A 5 x 4 cloud in mm, point (u, v) = (u, v, 1000 + 10 v + u) mm, intensity
  // u + v, with (1, 0) and (3, 2) invalid.
  sl::pipeline::PointCloud cloud;
  cloud.width = 5;
  cloud.height = 4;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int v = 0; v < 4; ++v)
    for (int u = 0; u < 5; ++u)
      cloud.points.push_back({float(u), float(v), 1000.0f + 10 * v + u, float(u + v)});
  cloud.points[1].z = cloud.points[3 + 2 * 5].z = nan;
  std::vector<float> buffer;
  auto point = [](const sl::dds::PackedCloud& p, std::size_t i) {
    const float* f = reinterpret_cast<const float*>(p.data) + 4 * i;
    return std::vector<float>{f[0], f[1], f[2], f[3]};
  };
  SECTION("metres, whole: the cloud's own memory") {
    const auto p = sl::dds::packCloud(cloud, 1.0, {}, buffer);
    CHECK(p.data == reinterpret_cast<const std::uint8_t*>(cloud.points.data()));
    CHECK(p.bytes == 20 * 16);
    CHECK((p.width == 5 && p.height == 4 && !p.dense));
  }
  SECTION("millimetres, every second pixel: 3 x 2, converted") {
    const auto p = sl::dds::packCloud(cloud, 1e-3, {2, false}, buffer);
    REQUIRE((p.width == 3 && p.height == 2 && p.bytes == 6 * 16 && !p.dense));
    CHECK(point(p, 1) == std::vector<float>{2e-3f, 0.0f, 1002.0f * 1e-3f, 2.0f});  // (2, 0)
    CHECK(point(p, 5) == std::vector<float>{4e-3f, 2e-3f, 1024.0f * 1e-3f, 6.0f});  // (4, 2)
  }
  SECTION("valid only: 18 points in row order, height 1, dense") {
    const auto p = sl::dds::packCloud(cloud, 1e-3, {1, true}, buffer);
    REQUIRE((p.width == 18 && p.height == 1 && p.bytes == 18 * 16 && p.dense));
    CHECK(point(p, 0)[2] == 1000.0f * 1e-3f);
    CHECK(point(p, 1)[2] == 1002.0f * 1e-3f);  // (1, 0) skipped
    for (std::size_t i = 0; i < 18; ++i) CHECK_FALSE(std::isnan(point(p, i)[2]));
  }
}

TEST_CASE("the DDS environment check names what the kernel or RouDi cannot give") {
  using sl::dds::DdsHost;
  // The shipped LAN config asks for 32 MiB / 8 MiB buffers.
  const auto lan = sl::dds::readDdsRequirements("file://" + std::string(SL_SOURCE_DIR) +
                                                   "/config/cyclonedds-lan.xml");
  REQUIRE(lan.receive_buffer_bytes);
  CHECK(*lan.receive_buffer_bytes == 32 << 20);
  CHECK(lan.send_buffer_bytes == std::optional<std::int64_t>(8 << 20));
  CHECK_FALSE(lan.shared_memory);
  const auto small = sl::dds::ddsEnvironmentProblems(lan, DdsHost{4 << 20, 4 << 20, false});
  REQUIRE(small.size() == 2);
  CHECK(small[0].find("32 MiB socket receive buffer but net.core.rmem_max is 4 MiB") !=
        std::string::npos);
  CHECK(small[0].find("99-sl-sensor-sysctl.conf") != std::string::npos);
  CHECK(small[1].find("net.core.wmem_max") != std::string::npos);
  CHECK(sl::dds::ddsEnvironmentProblems(lan, DdsHost{64 << 20, 16 << 20, false}).empty());
  // Inline XML, units, comments ignored; shared memory without RouDi.
  const auto inline_xml = sl::dds::readDdsRequirements(
      "<CycloneDDS><Domain><!-- <SocketReceiveBufferSize max=\"1GiB\"/> -->"
      "<Internal><SocketReceiveBufferSize min=\"default\" max=\"6000 KB\"/></Internal>"
      "<SharedMemory><Enable>true</Enable></SharedMemory></Domain></CycloneDDS>");
  CHECK(inline_xml.receive_buffer_bytes == std::optional<std::int64_t>(6'000'000));
  CHECK(inline_xml.shared_memory);
  const auto no_roudi =
      sl::dds::ddsEnvironmentProblems(inline_xml, DdsHost{4 << 20, 4 << 20, false});
  REQUIRE(no_roudi.size() == 2);
  CHECK(no_roudi[1].find("no iceoryx RouDi is running") != std::string::npos);
  CHECK(sl::dds::ddsEnvironmentProblems(inline_xml, DdsHost{8 << 20, 4 << 20, true}).empty());
  CHECK_THROWS_WITH(sl::dds::readDdsRequirements("file:///nonexistent/cyclone.xml"),
                    Catch::Contains("cannot read '/nonexistent/cyclone.xml'"));
}

TEST_CASE("the Cyclone config's addresses, peers, multicast and security, for the Fast DDS services") {
  const std::string config = std::string(SL_SOURCE_DIR) + "/config/";
  const auto loopback = sl::dds::readDdsRequirements("file://" + config + "cyclonedds-loopback.xml");
  CHECK(loopback.interface_addresses == std::vector<std::string>{"127.0.0.1"});
  CHECK(loopback.peer_addresses == std::vector<std::string>{"127.0.0.1"});
  CHECK_FALSE(loopback.allow_multicast);
  CHECK_FALSE(loopback.security);
  // Both files of a security setup, as Cyclone takes a comma-separated URI.
  const auto secure = sl::dds::readDdsRequirements("file://" + config + "cyclonedds-loopback.xml,file://" +
                                                   config + "cyclonedds-security.xml");
  CHECK(secure.security);
  // The older element, a commented-out address, a name instead of an address.
  const auto other = sl::dds::readDdsRequirements(
      "<CycloneDDS><Domain><General><NetworkInterfaceAddress>192.168.1.20</NetworkInterfaceAddress>"
      "<!-- <NetworkInterface address=\"10.0.0.1\"/> --><Interfaces><NetworkInterface name=\"eth0\"/>"
      "</Interfaces></General></Domain></CycloneDDS>");
  CHECK(other.interface_addresses == std::vector<std::string>{"192.168.1.20"});
  CHECK(other.peer_addresses.empty());
  CHECK(other.allow_multicast);
}

TEST_CASE("decoder.min_modulation takes a number or auto") {
  const auto numeric =
      sl::daemon::parseConfig(edited("min_modulation: auto", "min_modulation: 12"), "test.yaml");
  CHECK(numeric.decoder.min_modulation == 12.0f);
  const auto derived = sl::daemon::parseConfig(shippedConfig(), "test.yaml");
  CHECK(derived.decoder.min_modulation == sl::pipeline::kDerivedMinModulation);
}

TEST_CASE("decoder.projector_gamma / projector_response set the decoder's response") {
  const auto linear = sl::daemon::parseConfig(shippedConfig(), "test.yaml");
  CHECK(linear.decoder.projector_response.empty());
  const auto gamma = sl::daemon::parseConfig(
      edited("max_unwrap_error: 0.3", "max_unwrap_error: 0.3\n  projector_gamma: 2.2"), "test.yaml");
  CHECK(gamma.decoder.projector_response == sl::pipeline::gammaResponse(2.2));
  const auto table = sl::daemon::parseConfig(
      edited("max_unwrap_error: 0.3", "max_unwrap_error: 0.3\n  projector_response: [0, 0.2, 0.5, 1]"),
      "test.yaml");
  CHECK(table.decoder.projector_response == std::vector<float>{0.0f, 0.2f, 0.5f, 1.0f});
}

TEST_CASE("a missing file and malformed YAML are one clear error") {
  try {
    sl::daemon::loadConfig("/nonexistent/sl.yaml");
    FAIL("no error");
  } catch (const sl::files::ConfigError& e) {
    CHECK(std::string(e.what()) == "/nonexistent/sl.yaml: cannot open: No such file or directory (config file)");
  }
  const std::string message = errorOf("sensor: sim\nsim: {seed: [1,\n");
  CHECK(message.rfind("test.yaml:", 0) == 0);
  CHECK(message.find("malformed YAML") != std::string::npos);
  CHECK(errorOf("- just\n- a list\n").find("expected a map of keys at the top level") !=
        std::string::npos);
}

TEST_CASE("SLStudio's calibration.xml imports and round-trips through the project's format") {
  const std::string xml = std::string(SL_SHARED_DATA_DIR) + "/slstudio-skull/calibration.xml";
  const sl::files::CalibrationFile slstudio = sl::files::loadCalibration(xml);
  const auto& c = slstudio.calibration;
  CHECK(c.camera.width == 1688);
  CHECK(c.camera.height == 1352);
  CHECK(c.camera.fx == Approx(2195.12036));
  CHECK(c.camera.cy == Approx(675.5));
  CHECK(c.camera.distortion[0] == Approx(-0.0580352657));
  CHECK(c.projector.width == 1824);
  CHECK(c.projector.height == 1140);
  CHECK(c.projector.cy == Approx(1109.11121));
  CHECK(c.R(0, 2) == Approx(0.235467508));
  CHECK(c.t.x() == Approx(-145.282562));
  REQUIRE(slstudio.errors);
  CHECK(slstudio.errors->stereo_rms_px == Approx(0.4219975));

  const std::string yaml = "/tmp/sl_test_calibration_" + std::to_string(::getpid()) + ".yaml";
  sl::files::saveCalibration(slstudio, yaml);
  const sl::files::CalibrationFile again = sl::files::loadCalibration(yaml);
  std::remove(yaml.c_str());
  CHECK(again.calibration.camera.fx == c.camera.fx);
  CHECK(again.calibration.projector.distortion == c.projector.distortion);
  CHECK(again.calibration.R == c.R);  // 17 significant digits: exact
  CHECK(again.calibration.t == c.t);
  REQUIRE(again.errors);
  CHECK(again.errors->camera_rms_px == slstudio.errors->camera_rms_px);
  CHECK(again.source == slstudio.source);
}

TEST_CASE("calibration files that cannot be used are one clear error") {
  CHECK_THROWS_WITH(sl::files::loadCalibration("/nonexistent/c.yaml"),
                    "/nonexistent/c.yaml: calibration file not found");
  const std::string bad = "/tmp/sl_test_bad_calibration_" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(bad) << "format: sl-sensor-calibration/1\ncamera: {width: 10}\n";
  CHECK_THROWS_WITH(sl::files::loadCalibration(bad),
                    Catch::Contains("key 'camera.height' is required"));
  std::remove(bad.c_str());
}

// OpenCV 4.6's XML parser crashed (SEGV) on these, found by fuzz_calibration:
// malformed XML is refused, naming file and line, before OpenCV sees it.
TEST_CASE("malformed XML calibration files are refused before OpenCV parses them") {
  const std::string path = "/tmp/sl_test_bad_calibration_" + std::to_string(::getpid()) + ".xml";
  std::ofstream(path) << "<?xml versiveorsn=";  // the fuzzer's 18 bytes
  CHECK_THROWS_WITH(sl::files::loadCalibration(path),
                    Catch::StartsWith(path + ":1: malformed XML: "));
  std::ofstream(path) << "<?xml version=\"1.0\"?>\n<opencv_storage>\n<K type_id=\"opencv-matrix\">\n";
  CHECK_THROWS_WITH(sl::files::loadCalibration(path), Catch::Contains(": malformed XML: "));
  std::remove(path.c_str());
}

TEST_CASE("sensor: replay needs a readable recording and a calibration file") {
  std::string text = shippedConfig();
  text.replace(text.find("sensor: sim"), 11, "sensor: replay\nreplay: {dir: /nonexistent/rec}");
  std::string message = errorOf(text);
  CHECK(message.find("key 'replay.dir': /nonexistent/rec: not a recording") != std::string::npos);
  text = shippedConfig();
  text.replace(text.find("sensor: sim"), 11, "sensor: replay");
  message = errorOf(text);
  CHECK(message.find("key 'replay' is required") != std::string::npos);
}

TEST_CASE("log lines escape control characters and are bounded", "[log]") {
  using sl::daemon::logSafe;
  CHECK(logSafe("client a\nsl_sensord: forged\x1b[2J") ==
        "client a\\x0asl_sensord: forged\\x1b[2J");
  CHECK(logSafe("back\\slash\x7f") == "back\\\\slash\\x7f");
  CHECK(logSafe("caf\xc3\xa9") == "caf\xc3\xa9");  // UTF-8 stays readable
  const std::string big(1'000'000, 'x');
  const std::string cut = logSafe(big, 100);
  CHECK(cut.size() < 130);
  CHECK(cut.find("(1000000 bytes)") != std::string::npos);
}

TEST_CASE("a relative recording_root goes under systemd's state directory when there is one") {
  ::setenv("STATE_DIRECTORY", "/var/lib/sl-sensor", 1);
  const auto under_unit = sl::daemon::parseConfig(shippedConfig(), "/etc/sl-sensor/sim.yaml");
  ::unsetenv("STATE_DIRECTORY");
  CHECK(under_unit.runtime.recording_root == "/var/lib/sl-sensor/recordings");
  const auto by_hand = sl::daemon::parseConfig(shippedConfig(), "/etc/sl-sensor/sim.yaml");
  CHECK(by_hand.runtime.recording_root.rfind("/var/lib/sl-sensor", 0) == std::string::npos);
  CHECK(by_hand.runtime.recording_root.size() > std::string("/recordings").size());
}

TEST_CASE("a relative recording_root goes under the user's data folder, not beside the config") {
  const char* old_xdg = std::getenv("XDG_DATA_HOME");
  const char* old_home = std::getenv("HOME");
  const std::string saved_xdg = old_xdg ? old_xdg : "", saved_home = old_home ? old_home : "";
  ::unsetenv("STATE_DIRECTORY");
  ::setenv("XDG_DATA_HOME", "/home/u/data", 1);
  const auto xdg = sl::daemon::parseConfig(shippedConfig(), "/src/sl-sensor/config/sim.yaml");
  ::unsetenv("XDG_DATA_HOME");
  ::setenv("HOME", "/home/u", 1);
  const auto home = sl::daemon::parseConfig(shippedConfig(), "/src/sl-sensor/config/sim.yaml");
  if (old_xdg) ::setenv("XDG_DATA_HOME", saved_xdg.c_str(), 1);
  if (old_home) ::setenv("HOME", saved_home.c_str(), 1); else ::unsetenv("HOME");
  CHECK(xdg.runtime.recording_root == "/home/u/data/sl-sensor/recordings");
  CHECK(home.runtime.recording_root == "/home/u/.local/share/sl-sensor/recordings");
}

// Issue 36 item 1: inputs that are not regular files or not bounded are one
// ConfigError naming the file, refused before they are read (main hung on the
// FIFO, grew without bound on /dev/zero, hung on the alias bomb).
TEST_CASE("config files that are not regular, bounded, single YAML documents are refused",
          "[files]") {
  using sl::files::ConfigError;
  using sl::daemon::loadConfig;
  const std::string dir = "/tmp/sl_test_files_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  const auto refusedWith = [](const std::string& path, const std::string& words) {
    try {
      loadConfig(path);
    } catch (const ConfigError& e) {
      const std::string what = e.what();
      INFO(what);
      CHECK(what.rfind(path, 0) == 0);
      CHECK(what.find(words) != std::string::npos);
      return;
    }
    FAIL("accepted " << path);
  };
  const std::string fifo = dir + "/fifo.yaml";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  refusedWith(fifo, "FIFO");
  refusedWith("/dev/zero", "device");
  refusedWith(dir, "directory");
  {
    std::ofstream out(dir + "/bomb.yaml");
    out << "a: &a [x, x, x, x, x, x, x, x, x]\n";
    for (char c = 'b'; c <= 'z'; ++c)
      out << c << ": &" << c << " [*" << char(c - 1) << ", *" << char(c - 1) << ", *"
          << char(c - 1) << ", *" << char(c - 1) << "]\n";
  }
  refusedWith(dir + "/bomb.yaml", "aliases");
  std::ofstream(dir + "/two.yaml") << "sensor: sim\n---\nsensor: hardware\n";
  refusedWith(dir + "/two.yaml", "more than one YAML document");
  {
    std::ofstream out(dir + "/comments.yaml");
    const std::string line(1023, '#');
    for (int i = 0; i < 100 * 1024; ++i) out << line << '\n';  // 100 MB of comments
  }
  refusedWith(dir + "/comments.yaml", "more than the limit");
  std::filesystem::remove_all(dir);
}

TEST_CASE("a reload may change the decoder and dds.status_period_s; another dds key needs a restart") {
  const auto running = sl::daemon::parseConfig(shippedConfig(), "running.yaml");
  auto changed = [&](const std::string& from, const std::string& to) {
    return sl::daemon::keysNeedingRestart(running, sl::daemon::parseConfig(edited(from, to), "loaded.yaml"));
  };
  CHECK(changed("status_period_s: 1.0", "status_period_s: 2.0").empty());
  CHECK(changed("max_unwrap_error: 0.3", "max_unwrap_error: 0.4").empty());
  CHECK(changed("domain_id: 0", "domain_id: 3") == std::vector<std::string>{"dds.domain_id"});
}

namespace {

// An `adaptive:` section for the shipped sim config (motion compensation
// along x), with `extra` lines added to it and `moving` as given.
std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  REQUIRE(at != std::string::npos);
  return text.replace(at, from.size(), to);
}

std::string withAdaptive(const std::string& extra = "",
                         const std::string& moving = "{pause: true}") {
  return shippedConfig() +
         "\nadaptive:\n"
         "  velocity_topic: /robot/velocity\n" +
         extra +
         "  modes:\n"
         "    static: {pattern: 3+3_both}\n"
         "    linear_x: {pattern: 3+3_horizontal, motion_compensation: true}\n"
         "    linear_y: {pattern: 3+3_both}\n"
         "    moving: " +
         moving + "\n";
}

}  // namespace

TEST_CASE("adaptive: is off without the section, and parses its policy and modes", "[adaptive]") {
  using sl::daemon::AdaptiveMode;
  CHECK_FALSE(sl::daemon::parseConfig(shippedConfig(), "test.yaml").adaptive.enabled);
  const auto config = sl::daemon::parseConfig(
      withAdaptive("  velocity_timeout_s: 0.3\n  max_speed_m_s: 0.08\n  safe_mode: static\n"), "test.yaml");
  const sl::daemon::AdaptiveConfig& a = config.adaptive;
  CHECK(a.enabled);
  CHECK(a.velocity_topic == "robot/velocity");  // the leading '/' of a ROS 2 name dropped
  CHECK(a.velocity_timeout_s == 0.3);
  CHECK(a.max_speed_m_s == 0.08);
  CHECK(a.static_speed_m_s == 0.002);  // default
  CHECK(a.safe_mode == AdaptiveMode::kStatic);
  const auto& linear_x = a.actions[static_cast<std::size_t>(AdaptiveMode::kLinearX)];
  CHECK(linear_x.pattern == "3+3_horizontal");
  CHECK(linear_x.motion_compensation);
  CHECK_FALSE(a.actions[static_cast<std::size_t>(AdaptiveMode::kStatic)].motion_compensation);
  CHECK(a.actions[static_cast<std::size_t>(AdaptiveMode::kMoving)].pause);
  const auto moving = sl::daemon::parseConfig(withAdaptive("", "{pattern: 3+3_horizontal}"), "test.yaml");
  CHECK_FALSE(moving.adaptive.actions[static_cast<std::size_t>(AdaptiveMode::kMoving)].pause);
}

TEST_CASE("adaptive: mistakes name the key", "[adaptive]") {
  struct Case {
    std::string yaml, expected;
  };
  const auto c = GENERATE(
      Case{withAdaptive("  speed_limit: 1\n"), "unknown key 'adaptive.speed_limit'"},
      Case{withAdaptive("  max_speed_m_s: 0.001\n"), "key 'adaptive.max_speed_m_s': must be above static_speed_m_s"},
      Case{withAdaptive("  velocity_timeout_s: 0\n"), "key 'adaptive.velocity_timeout_s': must be in"},
      Case{withAdaptive("  safe_mode: stop\n"),
           "key 'adaptive.safe_mode': must be static, linear_x, linear_y or moving, not 'stop'"},
      Case{withAdaptive("", "{pattern: nope}"), "key 'adaptive.modes.moving.pattern': no pattern named 'nope'"},
      Case{withAdaptive("", "{pause: true, pattern: 3+3_both}"),
           "key 'adaptive.modes.moving.pause': a paused mode has no pattern"},
      Case{withAdaptive("", "{motion_compensation: true}"), "key 'adaptive.modes.moving.pattern'"},
      // linear_y cannot be compensated along motion_compensation.axis (x here).
      Case{replaced(withAdaptive(), "linear_y: {pattern: 3+3_both}",
                    "linear_y: {pattern: 3+3_both, motion_compensation: true}"),
           "key 'adaptive.modes.linear_y.motion_compensation': compensates along motion_compensation.axis (x)"},
      Case{shippedConfig() + "\nadaptive:\n  modes: {}\n", "key 'adaptive.velocity_topic'"},
      Case{shippedConfig() + "\nadaptive:\n  velocity_topic: a b\n", "key 'adaptive.velocity_topic': must be a ROS 2 topic name"});
  INFO(c.yaml);
  CHECK_THAT(errorOf(c.yaml), Catch::Matchers::Contains(c.expected));
}

TEST_CASE("adaptive: the example commented in config/sim-motion.yaml parses", "[adaptive]") {
  std::ifstream in(std::string(SL_SOURCE_DIR) + "/config/sim-motion.yaml");
  std::string text, line;
  bool in_example = false;
  while (std::getline(in, line)) {
    // The example: "# adaptive:" and the "#   ..." lines after it, uncommented.
    if (line == "# adaptive:") in_example = true;
    else if (in_example && line.rfind("#   ", 0) != 0) in_example = false;
    text += (in_example ? line.substr(2) : line) + "\n";
  }
  const auto config = sl::daemon::parseConfig(text, "sim-motion.yaml");
  using sl::daemon::AdaptiveMode;
  REQUIRE(config.adaptive.enabled);
  const auto& linear_x = config.adaptive.actions[static_cast<std::size_t>(AdaptiveMode::kLinearX)];
  CHECK(linear_x.pattern == "3+3_vertical");
  CHECK(linear_x.motion_compensation);
  CHECK(config.adaptive.actions[static_cast<std::size_t>(AdaptiveMode::kMoving)].pause);
  CHECK(config.adaptive.safe_mode == AdaptiveMode::kMoving);
}
