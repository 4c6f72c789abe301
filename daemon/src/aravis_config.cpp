#include "aravis_config_yaml.h"

#include <cstdint>
#include <set>

#include "sl/files/calibration_io.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::YamlMap;
using ::sl::files::kMaxImagePixels;
using ::sl::files::kMaxImageSide;

namespace {

using drivers::AravisCameraConfig;
using drivers::AravisTriggerConfig;

AravisTriggerConfig parseTrigger(const YamlMap& m) {
  AravisTriggerConfig t;
  const std::string mode = m.get<std::string>("mode", "hardware");
  if (mode == "hardware") t.mode = AravisTriggerConfig::Mode::kHardware;
  else if (mode == "software") t.mode = AravisTriggerConfig::Mode::kSoftware;
  else if (mode == "free_run") t.mode = AravisTriggerConfig::Mode::kFreeRun;
  else m.fail("mode", "must be hardware, software or free_run, not '" + mode + "'");
  if (t.mode == AravisTriggerConfig::Mode::kHardware) {
    t.line = m.get<std::string>("line", t.line);
    if (t.line.empty()) m.fail("line", "must not be empty");
    const std::string edge = m.get<std::string>("edge", "rising");
    if (edge == "rising") t.edge = AravisTriggerConfig::Edge::kRising;
    else if (edge == "falling") t.edge = AravisTriggerConfig::Edge::kFalling;
    else if (edge == "any") t.edge = AravisTriggerConfig::Edge::kAny;
    else m.fail("edge", "must be rising, falling or any, not '" + edge + "'");
  }
  if (t.mode == AravisTriggerConfig::Mode::kFreeRun)
    t.frame_rate_hz = nonNegative(m, "frame_rate_hz", t.frame_rate_hz);
  m.done();
  return t;
}

AravisCameraConfig parseCamera(const YamlMap& m) {
  AravisCameraConfig c;
  c.name = m.get<std::string>("name");
  if (c.name.empty()) m.fail("name", "must not be empty");
  c.device = m.get<std::string>("device");
  if (c.device.empty()) m.fail("device", "must not be empty (device id, serial number or IP)");
  c.pixel_format = m.get<std::string>("pixel_format", c.pixel_format);
  if (drivers::monoPixelFormatCode(c.pixel_format) == 0)
    m.fail("pixel_format", "unsupported '" + c.pixel_format +
                               "' (Mono8, Mono10, Mono12, Mono16, Mono10Packed, Mono12Packed, "
                               "Mono10p, Mono12p)");
  const YamlMap roi = m.optionalMap("roi");
  c.offset_x = roi.get<int>("x", c.offset_x);
  c.offset_y = roi.get<int>("y", c.offset_y);
  c.width = roi.get<int>("width", c.width);
  c.height = roi.get<int>("height", c.height);
  if (c.offset_x < 0) roi.fail("x", "must be >= 0");
  if (c.offset_y < 0) roi.fail("y", "must be >= 0");
  if (c.width < 0) roi.fail("width", "must be >= 0 (0 = the rest of the sensor)");
  if (c.height < 0) roi.fail("height", "must be >= 0 (0 = the rest of the sensor)");
  // Bounded before any buffer is sized by them.
  if (c.offset_x + std::int64_t{c.width} > kMaxImageSide)
    roi.fail("width", "x + width must be at most " + std::to_string(kMaxImageSide));
  if (c.offset_y + std::int64_t{c.height} > kMaxImageSide)
    roi.fail("height", "y + height must be at most " + std::to_string(kMaxImageSide));
  if (std::int64_t{c.width} * c.height > kMaxImagePixels)
    roi.fail("height", std::to_string(c.width) + " x " + std::to_string(c.height) + " is more than " +
                           std::to_string(kMaxImagePixels / 1'000'000) + " megapixels");
  roi.done();
  const YamlMap binning = m.optionalMap("binning");
  c.binning_horizontal = binning.get<int>("horizontal", c.binning_horizontal);
  c.binning_vertical = binning.get<int>("vertical", c.binning_vertical);
  if (c.binning_horizontal < 1 || c.binning_horizontal > 16) binning.fail("horizontal", "must be in 1..16");
  if (c.binning_vertical < 1 || c.binning_vertical > 16) binning.fail("vertical", "must be in 1..16");
  binning.done();
  if (m.has("exposure_us")) c.exposure_us = positive(m, "exposure_us", 0);
  if (m.has("gain")) c.gain = nonNegative(m, "gain", 0);
  c.trigger = parseTrigger(m.optionalMap("trigger"));
  const std::string timestamp = m.get<std::string>("timestamp", "host");
  if (timestamp == "host") c.timestamp = AravisCameraConfig::Timestamp::kHost;
  else if (timestamp == "device") c.timestamp = AravisCameraConfig::Timestamp::kDevice;
  else m.fail("timestamp", "must be host or device, not '" + timestamp + "'");
  c.host_latency_s = nonNegative(m, "host_latency_s", c.host_latency_s);
  const YamlMap gige = m.optionalMap("gige");
  c.packet_size = gige.get<int>("packet_size", c.packet_size);
  if (c.packet_size != 0 && (c.packet_size < 576 || c.packet_size > 16384))
    gige.fail("packet_size", "must be 0 (negotiate) or in 576..16384 bytes");
  c.packet_socket = gige.get<bool>("packet_socket", c.packet_socket);
  c.socket_buffer_bytes = static_cast<std::size_t>(
      gige.get<std::uint64_t>("socket_buffer_bytes", c.socket_buffer_bytes));
  c.frame_retention_ms = gige.get<int>("frame_retention_ms", c.frame_retention_ms);
  if (c.frame_retention_ms < 0 || c.frame_retention_ms > 10000)
    gige.fail("frame_retention_ms", "must be in 0..10000 (0 = Aravis' default)");
  gige.done();
  c.buffer_count = m.get<int>("buffers", c.buffer_count);
  if (c.buffer_count < 2 || c.buffer_count > 256) m.fail("buffers", "must be in 2..256");
  c.reconnect_interval_s = positive(m, "reconnect_interval_s", c.reconnect_interval_s);
  m.done();
  return c;
}

}  // namespace

void parseAravisSection(const YamlMap& root, DaemonConfig& config) {
  std::set<std::string> names;
  for (const YamlMap& m : root.listOfMaps("cameras")) {
    AravisCameraConfig c = parseCamera(m);
    if (!names.insert(c.name).second) m.fail("name", "duplicate camera name '" + c.name + "'");
    config.aravis.cameras.push_back(std::move(c));
  }
  if (config.sensor != SensorKind::kFakeGige) return;

  const YamlMap fake = root.map("fake_gige");
  drivers::FakeGigeOptions& o = config.aravis.fake;
  o.interface_address = fake.get<std::string>("interface", o.interface_address);
  o.serial = fake.get<std::string>("serial", o.serial);
  if (o.serial.empty()) fake.fail("serial", "must not be empty");
  fake.done();
  // One simulated camera: the fake GigE camera carries its images.
  if (config.aravis.cameras.size() != 1)
    root.fail("cameras", "sensor 'fake_gige' has exactly one camera (the simulated one)");
  AravisCameraConfig& c = config.aravis.cameras.front();
  const int w = config.sim.rig.camera.width, h = config.sim.rig.camera.height;
  if (c.width == 0) c.width = w;
  if (c.height == 0) c.height = h;
  const std::string format = config.sim.bit_depth > 8 ? "Mono16" : "Mono8";
  if (c.width != w || c.height != h || c.offset_x != 0 || c.offset_y != 0 ||
      c.binning_horizontal != 1 || c.binning_vertical != 1)
    root.fail("cameras", "the fake GigE camera carries the simulated " + std::to_string(w) + "x" +
                             std::to_string(h) + " images: roi must be 0, 0, " +
                             std::to_string(w) + ", " + std::to_string(h) + ", binning 1");
  if (c.pixel_format != format)
    root.fail("cameras", "pixel_format must be " + format + " for sim.bit_depth " +
                             std::to_string(config.sim.bit_depth));
  if (c.trigger.mode != AravisTriggerConfig::Mode::kSoftware)
    root.fail("cameras", "the fake GigE camera is triggered by the simulated schedule: "
                         "trigger mode must be software");
}

}  // namespace sl::daemon
