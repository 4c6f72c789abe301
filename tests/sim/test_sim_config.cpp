// The `sim:` section of the daemon config: the optics and electronics keys
// parse into SimConfig, and mistakes name the file, line and key.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "sl/daemon/config.h"
#include "sl/drivers/sim.h"
#include "support/config_text.h"

namespace {

std::string shippedSimConfig() { return sl::test::shippedSimConfigText(); }

// The shipped config with `lines` inserted under `sim.radiometry:`, the
// shipped lines of the same keys removed (a key given twice is an error).
std::string withRadiometry(const std::string& lines) {
  std::string text = shippedSimConfig();
  std::istringstream given(lines);
  for (std::string line; std::getline(given, line);) {
    const std::string key = line.substr(0, line.find(':') + 1);  // "    name:"
    const auto old = text.find("\n" + key);
    if (old != std::string::npos) text.erase(old + 1, text.find('\n', old + 1) - old);
  }
  const std::string anchor = "  radiometry:\n";
  const auto at = text.find(anchor);
  REQUIRE(at != std::string::npos);
  return text.insert(at + anchor.size(), lines);
}

std::string errorOf(const std::string& yaml) { return sl::test::configErrorOf(yaml); }

}  // namespace

TEST_CASE("sim config: projector response, exposure and gain keys", "[sim][config]") {
  const auto plain = sl::daemon::parseConfig(shippedSimConfig(), "test.yaml");
  CHECK(plain.sim.projector_gamma == 1.0);
  CHECK(plain.sim.projector_response.empty());

  const auto gamma =
      sl::daemon::parseConfig(withRadiometry("    projector_gamma: 2.2\n"), "t.yaml");
  CHECK(gamma.sim.projector_gamma == 2.2);
  const auto table =
      sl::daemon::parseConfig(withRadiometry("    projector_response: [0, 0.2, 1]\n"), "t.yaml");
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
      Case{"    exposure_ms: 40\n",
           "key 'sim.radiometry.exposure_ms': must fit in the frame interval"},
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
  const auto pinhole =
      sl::daemon::parseConfig(withCameraLens(lens, "camera: {f_number: 0}"), "t.yaml");
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

namespace {

// The shipped config with its scene list replaced by `scene_items` (lines
// indented for the list under sim.scene).
std::string withScene(const std::string& scene_items) {
  std::string text = shippedSimConfig();
  const auto begin = text.find("  scene:\n");
  REQUIRE(begin != std::string::npos);
  auto end = text.find("\n\n", begin);
  REQUIRE(end != std::string::npos);
  return text.replace(begin, end - begin, "  scene:\n" + scene_items);
}

}  // namespace

TEST_CASE("sim config: mesh files relative to the config, groups with one pose",
          "[sim][config][mesh]") {
  const auto dir =
      std::filesystem::temp_directory_path() / ("sl_sim_config_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir / "meshes");
  {
    std::ofstream ply(dir / "meshes" / "tri.ply");
    ply << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
           "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
           "end_header\n0 0 0\n0.1 0 0\n0 0.1 0\n3 0 1 2\n";
  }
  cv::Mat image(30, 40, CV_8UC1, cv::Scalar(51));
  image.at<std::uint8_t>(0, 0) = 255;
  REQUIRE(cv::imwrite((dir / "albedo.png").string(), image));
  const std::string scene =
      "    - plane: {point_mm: [0, 0, 700], normal: [0, 0, -1],\n"
      "              texture: {file: albedo.png, width_mm: 200, x_axis: [1, 1, 0]}}\n"
      "    - height_field: {origin_mm: [0, 0, 650], width_mm: 10, length_mm: 10, cell_mm: 1,\n"
      "                     roughness: {rms_mm: 0.1}, albedo_texture: albedo.png}\n"
      "    - height_field: {origin_mm: [0, 0, 650], width_mm: 39, length_mm: 29, cell_mm: 1,\n"
      "                     height_map: {file: albedo.png, min_mm: -1, max_mm: 4}}\n"
      "    - mesh: {file: meshes/tri.ply, scale: 1000, rotation_deg: [0, 0, 90],\n"
      "             translation_mm: [0, 0, 500], albedo: 0.5}\n"
      "    - group:\n"
      "        translation_mm: [10, 0, 600]\n"
      "        rotation_deg: [0, 0, 90]\n"
      "        items:\n"
      "          - sphere: {center_mm: [20, 0, 0], radius_mm: 5}\n"
      "          - mesh: {file: meshes/tri.ply}\n";
  {
    std::ofstream out(dir / "scene.yaml");
    out << withScene(scene);
  }
  const auto config = sl::daemon::loadConfig((dir / "scene.yaml").string());
  const auto& s = config.sim.scene;
  REQUIRE(s.planes.size() == 1);
  REQUIRE(s.planes[0].texture);
  CHECK(s.planes[0].texture->albedo.size() == cv::Size(40, 30));
  CHECK(s.planes[0].texture->albedo.at<float>(0, 0) == 1.0f);
  CHECK(s.planes[0].texture->albedo.at<float>(1, 1) == Approx(0.2));
  CHECK(s.planes[0].texture->width_mm == 200);
  CHECK(s.planes[0].texture->center == Eigen::Vector3d(0, 0, 700));  // defaults to point_mm
  CHECK(s.planes[0].texture->x_axis == Eigen::Vector3d(1, 1, 0));
  REQUIRE(s.height_fields.size() == 2);
  CHECK(s.height_fields[0].albedo_texture.size() == cv::Size(40, 30));
  // The image's grey levels 255 and 51 -> 4 and 0 mm, on the 30 x 40 grid.
  const cv::Mat& heights = s.height_fields[1].heights_mm;
  REQUIRE(heights.size() == cv::Size(40, 30));
  CHECK(heights.at<float>(0, 0) == Approx(4));
  CHECK(heights.at<float>(10, 10) == Approx(0).margin(1e-5));
  CHECK_FALSE(s.height_fields[1].roughness);
  REQUIRE(s.meshes.size() == 2);
  REQUIRE(s.spheres.size() == 1);
  CHECK(s.meshes[0].vertices.size() == 3);
  CHECK(s.meshes[0].vertices[1].x() == Approx(100));  // scaled to mm
  CHECK(s.meshes[0].albedo == 0.5);
  CHECK((s.meshes[0].pose * Eigen::Vector3d(100, 0, 0) - Eigen::Vector3d(0, 100, 500)).norm() <
        1e-9);
  // The group's pose moves its members: (20, 0, 0) turned 90 deg about z, + (10, 0, 600).
  CHECK((s.spheres[0].center - Eigen::Vector3d(10, 20, 600)).norm() < 1e-9);
  CHECK((s.meshes[1].pose.translation() - Eigen::Vector3d(10, 0, 600)).norm() < 1e-9);

  struct Case {
    std::string items, expected;
  };
  const auto c = GENERATE_COPY(
      Case{"    - mesh: {file: meshes/none.ply}\n", "key 'sim.scene[0].mesh.file': PLY file"},
      Case{"    - mesh: {file: " + (dir / "meshes" / "tri.ply").string() + ", colour: red}\n",
           "unknown key 'sim.scene[0].mesh.colour'"},
      Case{"    - group: {translation_mm: [0, 0, 1]}\n",
           "key 'sim.scene[0].group.items' is required"},
      Case{"    - height_field: {origin_mm: [0, 0, 600]}\n",
           "key 'sim.scene[0].height_field.roughness': give exactly one of 'roughness' and "
           "'height_map'"},
      Case{"    - height_field: {origin_mm: [0, 0, 600], height_map: {file: x.png, max_mm: -1}}\n",
           "key 'sim.scene[0].height_field.height_map.max_mm': must exceed min_mm"},
      Case{"    - plane: {point_mm: [0, 0, 1], texture: {file: /nonexistent.png, width_mm: 5}}\n",
           "key 'sim.scene[0].plane.texture.file': albedo texture '/nonexistent.png': cannot be "
           "opened"},
      Case{"    - plane: {point_mm: [0, 0, 1], texture: {file: " + (dir / "albedo.png").string() +
               "}}\n",
           "key 'sim.scene[0].plane.texture.width_mm' is required"},
      Case{"    - plane: {point_mm: [0, 0, 1], texture: {file: " + (dir / "albedo.png").string() +
               ", width_mm: 5, x_axis: [0, 0, 1]}}\n",
           "key 'sim.scene[0].plane.texture.x_axis': must not be (nearly) parallel"},
      Case{"    - group: {items: [{cube: {}}]}\n", "exactly one of 'plane' or 'sphere'"},
      Case{"    - group: {items: [{sphere: {center_mm: [0, 0, 1], radius_mm: -1}}]}\n",
           "key 'sim.scene[0].group.items[0].sphere.radius_mm': must be > 0"});
  INFO("scene: " << c.items);
  std::string message;
  try {
    sl::daemon::parseConfig(withScene(c.items), "test.yaml");
  } catch (const sl::files::ConfigError& e) {
    message = e.what();
  }
  INFO("message: " << message);
  CHECK(message.rfind("test.yaml:", 0) == 0);
  CHECK(message.find(c.expected) != std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST_CASE("sim config: signal_cache_mib", "[sim][config][cache]") {
  auto withCache = [](const std::string& value) {
    std::string text = shippedSimConfig();
    const auto at = text.find("\nsim:\n");
    REQUIRE(at != std::string::npos);
    return text.insert(at + 6, "  signal_cache_mib: " + value + "\n");
  };
  CHECK(sl::daemon::parseConfig(shippedSimConfig(), "t.yaml").sim.signal_cache_mib == 256);
  CHECK(sl::daemon::parseConfig(withCache("0"), "t.yaml").sim.signal_cache_mib == 0);
  CHECK(sl::daemon::parseConfig(withCache("64"), "t.yaml").sim.signal_cache_mib == 64);
  for (const std::string bad : {"-1", "lots", "2000000", "1.5"}) {
    INFO("signal_cache_mib: " << bad);
    const std::string message = errorOf(withCache(bad));
    INFO("message: " << message);
    CHECK(message.find("key 'sim.signal_cache_mib'") != std::string::npos);
  }
}
