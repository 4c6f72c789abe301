// The `sim:` section of the daemon config: the optics and electronics keys
// parse into SimConfig, and mistakes name the file, line and key.
#include <catch2/catch.hpp>

#include <fstream>
#include <sstream>
#include <string>

#include "sl/daemon/config.h"
#include "sl/drivers/sim.h"

namespace {

std::string shippedSimConfig() {
  std::ifstream in(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The shipped config with `lines` inserted under `sim.radiometry:`.
std::string withRadiometry(const std::string& lines) {
  std::string text = shippedSimConfig();
  const std::string anchor = "  radiometry:\n";
  const auto at = text.find(anchor);
  REQUIRE(at != std::string::npos);
  return text.insert(at + anchor.size(), lines);
}

std::string errorOf(const std::string& yaml) {
  try {
    sl::daemon::parseConfig(yaml, "test.yaml");
  } catch (const sl::daemon::ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("sim config: projector response, exposure and gain keys", "[sim][config]") {
  const auto plain = sl::daemon::parseConfig(shippedSimConfig(), "test.yaml");
  CHECK(plain.sim.projector_gamma == 1.0);
  CHECK(plain.sim.projector_response.empty());

  const auto gamma = sl::daemon::parseConfig(withRadiometry("    projector_gamma: 2.2\n"), "t.yaml");
  CHECK(gamma.sim.projector_gamma == 2.2);
  const auto table = sl::daemon::parseConfig(
      withRadiometry("    projector_response: [0, 0.2, 1]\n"), "t.yaml");
  CHECK(table.sim.projector_response == std::vector<double>{0, 0.2, 1});
  const auto exposure = sl::daemon::parseConfig(
      withRadiometry("    exposure_ms: 8\n    reference_exposure_ms: 2\n    analog_gain: 1.5\n"),
      "t.yaml");
  CHECK(exposure.sim.exposure_ms == 8);
  CHECK(exposure.sim.reference_exposure_ms == 2);
  CHECK(exposure.sim.analog_gain == 1.5);

  struct Case {
    std::string lines, expected;
  };
  const auto c = GENERATE(
      Case{"    projector_gamma: steep\n",
           "key 'sim.radiometry.projector_gamma': expected a number, found 'steep'"},
      Case{"    projector_gamma: 0\n", "key 'sim.radiometry.projector_gamma': must be > 0"},
      Case{"    projector_response: [0, 1.2]\n",
           "key 'sim.radiometry.projector_response': values must be in [0, 1]"},
      Case{"    projector_response: [0.5]\n",
           "key 'sim.radiometry.projector_response': needs at least 2 samples"},
      Case{"    projector_response: [0, 1]\n    projector_gamma: 2\n",
           "key 'sim.radiometry.projector_gamma': must be 1"},
      Case{"    projector_gama: 2\n", "unknown key 'sim.radiometry.projector_gama'"},
      Case{"    exposure_ms: 40\n", "key 'sim.radiometry.exposure_ms': must fit in the frame interval"},
      Case{"    analog_gain: -1\n", "key 'sim.radiometry.analog_gain': must be > 0"},
      Case{"    reference_exposure_ms: [1]\n",
           "key 'sim.radiometry.reference_exposure_ms': expected a number"});
  INFO("inserted: " << c.lines);
  const std::string message = errorOf(withRadiometry(c.lines));
  INFO("message: " << message);
  CHECK(message.rfind("test.yaml:", 0) == 0);
  CHECK(message.find(c.expected) != std::string::npos);
}

TEST_CASE("sim config: optics keys", "[sim][config]") {
  const auto plain = sl::daemon::parseConfig(shippedSimConfig(), "test.yaml");
  const sl::drivers::SimConfig defaults;
  // The shipped file states the built-in defaults.
  CHECK(plain.sim.camera_lens.f_number == defaults.camera_lens.f_number);
  CHECK(plain.sim.camera_lens.focus_distance_mm == defaults.camera_lens.focus_distance_mm);
  CHECK(plain.sim.camera_lens.pixel_pitch_um == defaults.camera_lens.pixel_pitch_um);
  CHECK(plain.sim.projector_lens.f_number == defaults.projector_lens.f_number);
  CHECK(plain.sim.projector_lens.pixel_pitch_um == defaults.projector_lens.pixel_pitch_um);

  auto withCameraLens = [](const std::string& from, const std::string& to) {
    std::string text = shippedSimConfig();
    const auto at = text.find(from);
    REQUIRE(at != std::string::npos);
    return text.replace(at, from.size(), to);
  };
  const std::string lens = "camera:    {focus_distance_mm: 550, f_number: 4, pixel_pitch_um: 3.45}";
  const auto pinhole = sl::daemon::parseConfig(
      withCameraLens(lens, "camera: {f_number: 0}"), "t.yaml");
  CHECK(pinhole.sim.camera_lens.f_number == 0);

  struct Case {
    std::string to, expected;
  };
  const auto c = GENERATE(
      Case{"camera: {f_number: -2}", "key 'sim.optics.camera.f_number': must be >= 0"},
      Case{"camera: {f_number: wide}", "key 'sim.optics.camera.f_number': expected a number"},
      Case{"camera: {focus_distance_mm: 10}",
           "key 'sim.optics.camera.focus_distance_mm': must exceed twice the focal length"},
      Case{"camera: {aperture: 2}", "unknown key 'sim.optics.camera.aperture'"});
  INFO("camera lens: " << c.to);
  const std::string message = errorOf(withCameraLens(lens, c.to));
  INFO("message: " << message);
  CHECK(message.rfind("test.yaml:", 0) == 0);
  CHECK(message.find(c.expected) != std::string::npos);
}
