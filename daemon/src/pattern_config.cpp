#include "sl/daemon/pattern_config.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "pattern_config_yaml.h"
#include "sl/daemon/config.h"

namespace sl::daemon {

namespace {

using pipeline::PatternFamily;
using pipeline::PatternSpec;

YAML::Node loadYaml(const std::string& text, const std::string& origin) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
}

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open pattern file");
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

void parseSinusoid(const YamlMap& m, PatternSpec& p) {
  p.shift_sign = m.get<int>("shift_sign", p.shift_sign);
  if (p.shift_sign != 1 && p.shift_sign != -1) m.fail("shift_sign", "must be 1 or -1");
  p.start_phase_rad = m.get<double>("start_phase_deg", 0.0) * std::numbers::pi / 180.0;
  p.offset = m.get<double>("offset", p.offset);
  p.amplitude = m.get<double>("amplitude", p.amplitude);
  if (!(p.amplitude > 0 && p.offset - p.amplitude >= 0 && p.offset + p.amplitude <= 1))
    m.fail("amplitude", "need amplitude > 0 and 0 <= offset +- amplitude <= 1");
}

void parseGray(const YamlMap& m, PatternSpec& p) {
  p.gray_bits = m.get<int>("bits", 0);
  if (p.gray_bits < 0) m.fail("bits", "must be >= 0 (0 = all bits)");
  p.gray_inverse = m.get<bool>("inverse", p.gray_inverse);
  p.reference_frames = m.get<bool>("reference_frames", p.reference_frames);
}

std::vector<double> frequencies(const YamlMap& m) {
  const auto f = m.get<std::vector<double>>("frequencies");
  if (f.empty()) m.fail("frequencies", "must not be empty");
  return f;
}

}  // namespace

PatternSpec parsePattern(const YamlMap& m, const std::string& name,
                         const pipeline::PinholeModel* projector, const std::string& base_dir) {
  if (m.has("file")) {
    // A daemon list item pointing at a pattern file: only `name` may be added.
    std::filesystem::path path(m.get<std::string>("file"));
    if (path.is_relative()) path = std::filesystem::path(base_dir) / path;
    if (!std::filesystem::exists(path))
      m.fail("file", "cannot read pattern file '" + path.string() + "'");
    PatternSpec p = loadPattern(path.string());
    p.name = m.get<std::string>("name", p.name);
    m.done();
    if (projector && (p.projector_width != projector->width ||
                      p.projector_height != projector->height))
      m.fail("file", "pattern '" + p.name + "' is for a " + std::to_string(p.projector_width) +
                         "x" + std::to_string(p.projector_height) + " projector, the calibration's is " +
                         std::to_string(projector->width) + "x" + std::to_string(projector->height));
    return p;
  }
  PatternSpec p;
  p.name = name.empty() ? m.get<std::string>("name") : m.get<std::string>("name", name);
  if (p.name.empty()) m.fail("name", "must not be empty");
  const std::string family = m.get<std::string>("family", "phase_shift_3+3");
  try {
    p.direction = pipeline::directionFromString(m.get<std::string>("direction"));
  } catch (const std::invalid_argument& e) {
    m.fail("direction", e.what());
  }
  if (projector) {
    p.projector_width = projector->width;
    p.projector_height = projector->height;
  }
  if (m.has("projector")) {
    const YamlMap size = m.map("projector");
    const int w = size.get<int>("width"), h = size.get<int>("height");
    size.done();
    if (w <= 0 || h <= 0) m.fail("projector", "width and height must be > 0");
    if (projector && (w != projector->width || h != projector->height))
      m.fail("projector", "differs from the calibration's projector (" +
                              std::to_string(projector->width) + "x" +
                              std::to_string(projector->height) + ")");
    p.projector_width = w;
    p.projector_height = h;
  }
  std::string check_key = "family";  // key blamed when validate() fails
  if (family == "phase_shift_3+3") {
    // The paper's 3+3: 3 steps at `fringes` periods, then 3 at unit frequency.
    p.family = PatternFamily::kPhaseShift;
    p.steps = 3;
    p.frequencies = {static_cast<double>(m.get<int>("fringes", 16)), 1.0};
    check_key = "fringes";
  } else {
    try {
      p.family = pipeline::patternFamilyFromString(family);
    } catch (const std::invalid_argument& e) {
      m.fail("family", e.what());
    }
    switch (p.family) {
      case PatternFamily::kPhaseShift:
        p.steps = m.get<int>("steps", 3);
        p.frequencies = frequencies(m);
        try {
          p.unwrapping = pipeline::unwrappingFromString(
              m.get<std::string>("unwrapping", "hierarchical"));
        } catch (const std::invalid_argument& e) {
          m.fail("unwrapping", e.what());
        }
        parseSinusoid(m, p);
        check_key = "frequencies";
        break;
      case PatternFamily::kTwoPlusOne:
        p.frequencies = frequencies(m);
        parseSinusoid(m, p);
        check_key = "frequencies";
        break;
      case PatternFamily::kGrayCode:
        parseGray(m, p);
        check_key = "bits";
        break;
      case PatternFamily::kGrayPhaseShift:
        p.steps = m.get<int>("steps", 4);
        parseGray(m, p);
        p.complementary = m.get<bool>("complementary", p.complementary);
        parseSinusoid(m, p);
        check_key = "bits";
        break;
    }
  }
  if (m.has("frame_order")) {
    for (double v : m.get<std::vector<double>>("frame_order")) {
      if (v != std::floor(v) || v < 0) m.fail("frame_order", "must list frame indices (integers >= 0)");
      p.frame_order.push_back(static_cast<int>(v));
    }
    std::vector<int> sorted = p.frame_order;
    std::sort(sorted.begin(), sorted.end());
    bool permutation = static_cast<int>(sorted.size()) == p.frameCount();
    for (std::size_t i = 0; permutation && i < sorted.size(); ++i)
      permutation = sorted[i] == static_cast<int>(i);
    if (!permutation)
      m.fail("frame_order", "must be a permutation of 0.." + std::to_string(p.frameCount() - 1));
  }
  try {
    p.validate();
  } catch (const std::invalid_argument& e) {
    m.fail(check_key, e.what());
  }
  m.done();
  return p;
}

PatternSpec parsePatternText(const std::string& yaml_text, const std::string& origin,
                             const std::string& default_name) {
  const YAML::Node root = loadYaml(yaml_text, origin);
  if (!root.IsMap()) throw ConfigError(origin + ": expected a map of pattern keys");
  const YamlMap m(root, origin, "");
  return parsePattern(m, default_name, nullptr,
                      std::filesystem::path(origin).parent_path().string());
}

PatternSpec loadPattern(const std::string& path) {
  return parsePatternText(readFile(path), path, std::filesystem::path(path).stem().string());
}

}  // namespace sl::daemon
