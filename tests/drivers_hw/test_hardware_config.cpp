// `sensor: hardware`: the example config loads into the driver structs, and
// mistakes give one line naming file, line and key.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "sl/daemon/config.h"

using namespace sl;

namespace {

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Writes the example with `from` replaced by `to` beside a copy of its
// calibration file and loads it.
daemon::DaemonConfig loadVariant(const std::string& from, const std::string& to) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("sl_hw_config_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(SL_SOURCE_DIR "/config/hardware-paper-calibration.yaml",
                             dir / "hardware-paper-calibration.yaml",
                             std::filesystem::copy_options::overwrite_existing);
  std::string text = readFile(SL_SOURCE_DIR "/config/hardware-paper.yaml");
  if (!from.empty()) {
    const auto at = text.find(from);
    REQUIRE(at != std::string::npos);
    text.replace(at, from.size(), to);
  }
  std::ofstream(dir / "c.yaml") << text;
  return daemon::loadConfig((dir / "c.yaml").string());
}

}  // namespace

TEST_CASE("config/hardware-paper.yaml loads into the driver structs") {
  const daemon::DaemonConfig c = daemon::loadConfig(SL_SOURCE_DIR "/config/hardware-paper.yaml");
  CHECK(c.sensor == sl::daemon::SensorKind::kHardware);
  const auto& p = c.hardware.projector;
  CHECK(p.vendor_id == 0x0451);
  CHECK(p.product_id == 0x6401);
  CHECK(p.led_current_green == 60);
  REQUIRE(p.sequences.size() == 3);
  CHECK(p.sequences[0].name == "3+3_horizontal");
  CHECK(p.sequences[0].patterns.size() == 6);
  CHECK(p.sequences[0].patterns[3].image_index == 8);
  CHECK(p.sequences[0].first_trigger == drivers::dlpc350::TriggerType::kExternalPositive);
  CHECK(p.sequences[2].patterns.size() == 12);
  CHECK(p.reply_timeout == std::chrono::milliseconds(1000));
  CHECK(c.hardware.trigger == daemon::HardwareConfig::Trigger::kVersavis);
  CHECK(c.hardware.versavis.device == "/dev/versavis");
  CHECK(c.hardware.versavis.baud == 250000);
  CHECK(c.hardware.versavis.topic == "/versavis/projector/image_time");
  CHECK(c.synchroniser.image_interval_ns == 33333000);
  CHECK_FALSE(p.led_pwm_polarity_inverted);
  const auto& v = c.hardware.versavis;
  CHECK(v.camera_channels == std::vector<std::string>{"/versavis/cam1/", "/versavis/cam1/"});
  CHECK(v.init_matches == 2);
  CHECK(v.restamp_wait == std::chrono::milliseconds(200));
  CHECK(v.sync_timeout == std::chrono::milliseconds(15000));
  CHECK(v.watchdog == std::chrono::milliseconds(3000));
  CHECK(v.reset_at_start);
  CHECK(v.tx_stop_at_close);
  CHECK_THROWS_WITH(loadVariant("camera_channels: [/versavis/cam1/, /versavis/cam1/]",
                                "camera_channels: [/versavis/cam1, /versavis/cam1/]"),
                    Catch::Contains("key 'trigger.versavis.camera_channels': expected topic "
                                    "prefixes like /versavis/cam1/, not '/versavis/cam1'"));
}

TEST_CASE("white / black channels (Gray-code reference frames) follow the fill polarity") {
  const daemon::DaemonConfig c = loadVariant(
      "channels:      [0, 1, 2, 0, 1, 2]\n      bit_depths:    [8, 8, 8, 8, 8, 8]",
      "channels:      [white, black, 2, 0, 1, 2]\n      bit_depths:    [1, 1, 8, 8, 8, 8]");
  const auto& s = c.hardware.projector.sequences[0];
  const auto white = drivers::dlpc350::fillPattern(true);
  CHECK(s.patterns[0].channel == white.pattern_number);
  CHECK(s.patterns[0].bit_depth == 1);
  CHECK(s.patterns[0].invert == white.invert);
  CHECK(s.patterns[0].invert);  // 24 inverted = white
  CHECK(s.patterns[1].channel == 24);
  CHECK_FALSE(s.patterns[1].invert);  // 24 = black
  CHECK(s.patterns[2].channel == 2);
  CHECK_THROWS_WITH(
      loadVariant("channels:      [0, 1, 2, 0, 1, 2]\n      bit_depths:    [8, 8, 8, 8, 8, 8]",
                  "channels:      [white, 1, 2, 0, 1, 2]\n      bit_depths:    [8, 8, 8, 8, 8, 8]"),
      Catch::Contains("entry 0 is the white fill pattern: bit depth 1"));
  CHECK_THROWS_WITH(
      loadVariant("channels:      [0, 1, 2, 0, 1, 2]", "channels:      [grey, 1, 2, 0, 1, 2]"),
      Catch::Contains("expected integers in 0..24 or white / black"));
}

TEST_CASE("hardware config mistakes name file, line and key") {
  CHECK_THROWS_WITH(loadVariant("leds: white", "leds: purple"),
                    Catch::Matches(".*c.yaml:[0-9]+: key 'projector.sequences\\[0\\].leds': .*"));
  CHECK_THROWS_WITH(
      loadVariant("channels:      [0, 1, 2, 0, 1, 2]", "channels:      [0, 1, 3, 0, 1, 2]"),
      Catch::Contains("key 'projector.sequences[0].channels': sequence "
                      "'3+3_horizontal': pattern 2: pattern number 3 not in 0..2"));
  CHECK_THROWS_WITH(loadVariant("usb_serial:", "usb_serail:"),
                    Catch::Contains("unknown key 'projector.usb_serail'"));
  CHECK_THROWS_WITH(loadVariant("type: versavis ", "type: board "),
                    Catch::Contains("key 'trigger.type': unknown trigger 'board'"));
  CHECK_THROWS_WITH(loadVariant("- name: 3+3_vertical", "- name: 3+3_vert"),
                    Catch::Contains("no sequence for pattern '3+3_vertical'"));
  CHECK_THROWS_WITH(
      loadVariant("calibration: hardware-paper-calibration.yaml", "calibration: sim"),
      Catch::Contains("key 'calibration': a hardware sensor needs a calibration file"));
  CHECK_THROWS_WITH(loadVariant("    negotiation_retry_s: 2.0",
                                "    negotiation_retry_s: 2.0\n  camera_stamps: {offset_us: 3}"),
                    Catch::Contains("key 'trigger.camera_stamps': given, but trigger.type is"));
  CHECK_THROWS_WITH(
      loadVariant("image_indices: [7, 7, 7, 8, 8, 8, 9", "image_indices: [7, 7, 7, 8, 8, 9"),
      Catch::Contains("needs one entry per image index (11)"));
  CHECK_THROWS_WITH(loadVariant("type: versavis ", "type: camera_stamps "),
                    Catch::Contains("key 'trigger.versavis': given, but trigger.type is "
                                    "'camera_stamps'"));
}
