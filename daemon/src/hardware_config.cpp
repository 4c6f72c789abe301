#include <cmath>
#include <optional>
#include <set>

#include "hardware_config_yaml.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::YamlMap;

namespace {

namespace dl = drivers::dlpc350;

std::vector<int> intList(const YamlMap& m, const std::string& key, int lo, int hi) {
  std::vector<int> out;
  for (double v : m.get<std::vector<double>>(key)) {
    if (v != std::floor(v) || v < lo || v > hi)
      m.fail(key, "expected integers in " + std::to_string(lo) + ".." + std::to_string(hi));
    out.push_back(static_cast<int>(v));
  }
  if (out.empty()) m.fail(key, "expected a non-empty list");
  return out;
}

std::uint32_t microseconds(const YamlMap& m, const std::string& key, std::uint32_t fallback) {
  const double v = m.get<double>(key, fallback);
  if (!(v >= 1 && v <= 4e9) || v != std::floor(v)) m.fail(key, "expected whole microseconds > 0");
  return static_cast<std::uint32_t>(v);
}

std::chrono::milliseconds millis(const YamlMap& m, const std::string& key,
                                 std::chrono::milliseconds fallback) {
  return std::chrono::milliseconds(
      std::llround(1000 * positive(m, key, static_cast<double>(fallback.count()) / 1000)));
}

std::uint8_t ledSelect(const YamlMap& m) {
  if (!m.has("leds")) return dl::kLedWhite;
  const std::string s = m.get<std::string>("leds");
  static const std::pair<const char*, std::uint8_t> names[] = {
      {"red", 1},     {"green", 2}, {"yellow", 3}, {"blue", 4},
      {"magenta", 5}, {"cyan", 6},  {"white", 7}};
  for (const auto& [name, bits] : names)
    if (s == name) return bits;
  m.fail("leds", "expected red, green, blue, yellow, magenta, cyan or white, not '" + s + "'");
}

dl::TriggerType triggerType(const YamlMap& m) {
  const std::string s = m.get<std::string>("first_trigger", "internal");
  if (s == "internal") return dl::TriggerType::kInternal;
  if (s == "external_positive") return dl::TriggerType::kExternalPositive;
  if (s == "external_negative") return dl::TriggerType::kExternalNegative;
  m.fail("first_trigger",
         "expected internal, external_positive or external_negative, not '" + s + "'");
}

drivers::LightCrafter4500Sequence parseSequence(const YamlMap& m) {
  drivers::LightCrafter4500Sequence s;
  s.name = m.get<std::string>("name");
  if (s.name.empty()) m.fail("name", "must not be empty");
  const std::vector<int> images = intList(m, "image_indices", 0, 255);
  // Channels: a pattern number 0..24, or "white" / "black" for the 1-bit
  // fill pattern with the polarity of dlpc350::fillPattern (Gray-code
  // reference frames), which sets its bit depth and invert flag.
  std::vector<int> channels;
  std::vector<std::optional<bool>> fill;  // white / black entries
  {
    const YAML::Node node = m.raw("channels");
    if (!node.IsSequence() || node.size() == 0)
      m.fail("channels", "expected a non-empty list of pattern numbers or white / black");
    for (std::size_t i = 0; i < node.size(); ++i) {
      const std::string text = node[i].IsScalar() ? node[i].Scalar() : std::string();
      if (text == "white" || text == "black") {
        const dl::FillPattern f = dl::fillPattern(text == "white");
        channels.push_back(f.pattern_number);
        fill.push_back(text == "white");
        continue;
      }
      int v = -1;
      try {
        const double d = node[i].as<double>();
        if (d == std::floor(d) && d >= 0 && d <= 24) v = static_cast<int>(d);
      } catch (const YAML::Exception&) {
      }
      if (v < 0) m.fail("channels", "expected integers in 0..24 or white / black");
      channels.push_back(v);
      fill.push_back(std::nullopt);
    }
  }
  std::vector<int> depths =
      m.has("bit_depths") ? intList(m, "bit_depths", 1, 8) : std::vector<int>(images.size(), 8);
  std::vector<bool> invert(images.size(), false);
  if (m.has("invert")) {
    const YAML::Node node = m.raw("invert");
    if (!node.IsSequence() || node.size() != images.size())
      m.fail("invert", "expected a list of " + std::to_string(images.size()) + " booleans");
    for (std::size_t i = 0; i < node.size(); ++i) {
      try {
        invert[i] = node[i].as<bool>();
      } catch (const YAML::Exception&) {
        m.fail("invert", "expected booleans (true/false)");
      }
    }
  }
  if (channels.size() != images.size())
    m.fail("channels", "needs one entry per image index (" + std::to_string(images.size()) + ")");
  if (depths.size() != images.size())
    m.fail("bit_depths", "needs one entry per image index (" + std::to_string(images.size()) + ")");
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (fill[i]) {
      if (m.has("bit_depths") && depths[i] != 1)
        m.fail("bit_depths", "entry " + std::to_string(i) + " is the " +
                                 (*fill[i] ? "white" : "black") + " fill pattern: bit depth 1");
      if (invert[i])
        m.fail("invert", "entry " + std::to_string(i) +
                             " is white / black: its polarity comes from the name");
      const dl::FillPattern f = dl::fillPattern(*fill[i]);
      depths[i] = f.bit_depth;
      invert[i] = f.invert;
    }
    s.patterns.push_back({images[i], channels[i], depths[i], invert[i]});
  }
  s.leds = ledSelect(m);
  s.exposure_us = microseconds(m, "exposure_us", s.exposure_us);
  s.frame_period_us = microseconds(m, "frame_period_us", s.exposure_us);
  s.first_trigger = triggerType(m);
  try {
    drivers::validateSequence(s);
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    const char* key = what.find("pattern number") != std::string::npos ? "channels"
                      : what.find("bit depth") != std::string::npos    ? "bit_depths"
                      : what.find("exposure") != std::string::npos ||
                              what.find("frame_period") != std::string::npos
                          ? "exposure_us"
                          : "image_indices";
    m.fail(key, what);
  }
  m.done();
  return s;
}

void parseProjector(const YamlMap& m, drivers::LightCrafter4500Config& p) {
  const std::string type = m.get<std::string>("type", "lightcrafter4500");
  if (type != "lightcrafter4500")
    m.fail("type", "unknown projector '" + type + "' (supported: lightcrafter4500)");
  p.id = m.get<std::string>("id", p.id);
  const int vendor = m.get<int>("usb_vendor_id", p.vendor_id);
  const int product = m.get<int>("usb_product_id", p.product_id);
  if (vendor < 0 || vendor > 0xFFFF) m.fail("usb_vendor_id", "must be in 0..0xFFFF");
  if (product < 0 || product > 0xFFFF) m.fail("usb_product_id", "must be in 0..0xFFFF");
  p.vendor_id = static_cast<std::uint16_t>(vendor);
  p.product_id = static_cast<std::uint16_t>(product);
  p.serial = m.get<std::string>("usb_serial", p.serial);
  if (m.has("led_currents")) {
    const std::vector<int> c = intList(m, "led_currents", 0, 255);
    if (c.size() != 3) m.fail("led_currents", "expected [red, green, blue]");
    p.led_current_red = static_cast<std::uint8_t>(c[0]);
    p.led_current_green = static_cast<std::uint8_t>(c[1]);
    p.led_current_blue = static_cast<std::uint8_t>(c[2]);
  }
  p.led_pwm_inverted = m.get<bool>("led_pwm_inverted", p.led_pwm_inverted);
  p.led_pwm_polarity_inverted =
      m.get<bool>("led_pwm_polarity_inverted", p.led_pwm_polarity_inverted);
  const YamlMap out1 = m.optionalMap("trigger_out1");
  p.trigger_out1_invert = out1.get<bool>("invert", p.trigger_out1_invert);
  p.trigger_out1_rising_delay_us = out1.get<double>("rising_delay_us", 0);
  p.trigger_out1_falling_delay_us = out1.get<double>("falling_delay_us", 0);
  for (const char* key : {"rising_delay_us", "falling_delay_us"}) {
    try {
      dl::triggerDelayRaw(out1.get<double>(key, 0));
    } catch (const std::invalid_argument& e) {
      out1.fail(key, e.what());
    }
  }
  out1.done();
  p.reply_timeout = millis(m, "reply_timeout_s", p.reply_timeout);
  p.validation_timeout = millis(m, "validation_timeout_s", p.validation_timeout);
  p.power_up_timeout = millis(m, "power_up_timeout_s", p.power_up_timeout);
  p.white_black_period_us = microseconds(m, "white_black_period_us", p.white_black_period_us);
  std::set<std::string> names{"white", "black"};
  for (const YamlMap& item : m.listOfMaps("sequences")) {
    drivers::LightCrafter4500Sequence s = parseSequence(item);
    if (!names.insert(s.name).second)
      item.fail("name", "duplicate sequence name '" + s.name + "' (white and black are built in)");
    p.sequences.push_back(std::move(s));
  }
  m.done();
}

void parseTrigger(const YamlMap& m, HardwareConfig& h) {
  const std::string type = m.get<std::string>("type");
  if (type == "versavis") {
    h.trigger = HardwareConfig::Trigger::kVersavis;
    const YamlMap v = m.optionalMap("versavis");
    auto& c = h.versavis;
    c.device = v.get<std::string>("device", c.device);
    c.baud = v.get<int>("baud", c.baud);
    if (c.baud <= 0) v.fail("baud", "must be > 0");
    c.topic = v.get<std::string>("topic", c.topic);
    c.message_type = v.get<std::string>("message_type", c.message_type);
    c.triggers_per_sequence = v.get<int>("triggers_per_sequence", c.triggers_per_sequence);
    if (c.triggers_per_sequence < 1) v.fail("triggers_per_sequence", "must be >= 1");
    c.offset_ns = std::llround(1000 * v.get<double>("offset_us", 0));
    c.reconnect_interval = millis(v, "reconnect_interval_s", c.reconnect_interval);
    c.negotiation_retry = millis(v, "negotiation_retry_s", c.negotiation_retry);
    if (v.has("camera_channels")) {
      const YAML::Node node = v.raw("camera_channels");
      if (!node.IsSequence()) v.fail("camera_channels", "expected a list of topic prefixes");
      c.camera_channels.clear();
      for (const auto& item : node) {
        const std::string prefix = item.IsScalar() ? item.Scalar() : std::string();
        if (prefix.empty() || prefix.front() != '/' || prefix.back() != '/')
          v.fail("camera_channels",
                 "expected topic prefixes like /versavis/cam1/, not '" + prefix + "'");
        c.camera_channels.push_back(prefix);
      }
    }
    c.init_matches = v.get<int>("init_matches", c.init_matches);
    if (c.init_matches < 1) v.fail("init_matches", "must be >= 1");
    c.max_arrival_delay = millis(v, "max_arrival_delay_s", c.max_arrival_delay);
    c.restamp_wait = millis(v, "restamp_wait_s", c.restamp_wait);
    c.camera_offset_ns = std::llround(1000 * v.get<double>("camera_offset_us", 0));
    c.sync_timeout = millis(v, "sync_timeout_s", c.sync_timeout);
    c.watchdog = millis(v, "watchdog_s", c.watchdog);
    c.reset_at_start = v.get<bool>("reset_at_start", c.reset_at_start);
    c.reset_topic = v.get<std::string>("reset_topic", c.reset_topic);
    c.tx_stop_at_close = v.get<bool>("tx_stop_at_close", c.tx_stop_at_close);
    v.done();
  } else if (type == "camera_stamps") {
    h.trigger = HardwareConfig::Trigger::kCameraStamps;
    const YamlMap v = m.optionalMap("camera_stamps");
    auto& c = h.camera_stamps;
    c.max_gap_sequences = positive(v, "max_gap_sequences", c.max_gap_sequences);
    c.offset_ns = std::llround(1000 * v.get<double>("offset_us", 0));
    v.done();
  } else {
    m.fail("type", "unknown trigger '" + type + "' (supported: versavis, camera_stamps)");
  }
  // The section of the other type must not be there: it would be ignored.
  for (const char* other : {"versavis", "camera_stamps"})
    if (other != type && m.has(other))
      m.fail(other, std::string("given, but trigger.type is '") + type + "'");
  m.done();
}

const drivers::LightCrafter4500Sequence* findSequence(const drivers::LightCrafter4500Config& p,
                                                      const std::string& name) {
  for (const auto& s : p.sequences)
    if (s.name == name) return &s;
  return nullptr;
}

}  // namespace

void parseHardware(const YamlMap& root, DaemonConfig& config) {
  const YamlMap projector = root.map("projector");
  parseProjector(projector, config.hardware.projector);
  parseTrigger(root.map("trigger"), config.hardware);
  for (const auto& pattern : config.patterns) {
    const auto* s = findSequence(config.hardware.projector, pattern.name);
    if (!s)
      projector.fail("sequences", "no sequence for pattern '" + pattern.name +
                                      "' (each pattern needs a projector sequence of its name)");
    if (static_cast<int>(s->patterns.size()) != pattern.frameCount())
      projector.fail("sequences", "sequence '" + s->name + "' has " +
                                      std::to_string(s->patterns.size()) + " patterns, pattern '" +
                                      pattern.name + "' needs " +
                                      std::to_string(pattern.frameCount()));
  }
}

double hardwareImageRate(const YamlMap& root, const DaemonConfig& config) {
  std::uint32_t period = 0;
  for (const auto& pattern : config.patterns) {
    const auto* s = findSequence(config.hardware.projector, pattern.name);
    if (period != 0 && s->frame_period_us != period)
      root.fail("projector",
                "the patterns' sequences must share one frame_period_us (the "
                "synchroniser's image interval)");
    period = s->frame_period_us;
  }
  return 1e6 / period;
}

}  // namespace sl::daemon
