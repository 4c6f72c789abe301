#include "sl/files/pattern_config.h"

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "sl/files/pattern_config_yaml.h"
#include "sl/files/config_error.h"
#include "sl/files/input_file.h"

namespace sl::files {

namespace {

using pipeline::PatternFamily;
using pipeline::PatternSpec;

YAML::Node loadYaml(const std::string& text, const std::string& origin) {
  try {
    return parseInputYaml(text, origin);
  } catch (const YAML::Exception& e) {
    throw ConfigError(origin + ":" + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
  }
}

std::string readFile(const std::string& path) {
  return readInputFile(path, InputKind::kPattern);
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
  if (m.has("pitch_px")) {
    if (m.has("bits")) m.fail("pitch_px", "give one of 'bits' and 'pitch_px' (stripe width, px)");
    p.gray_pitch_px = m.get<double>("pitch_px");
    if (!(p.gray_pitch_px > 0 && std::isfinite(p.gray_pitch_px))) m.fail("pitch_px", "must be > 0");
  }
  p.gray_inverse = m.get<bool>("inverse", p.gray_inverse);
  p.reference_frames = m.get<bool>("reference_frames", p.reference_frames);
}

// Axis (px) every sinusoid of `p` runs along; pitches in px need one axis.
int pitchAxis(const YamlMap& m, const PatternSpec& p, const char* key) {
  if (p.direction == pipeline::Direction::kBoth && p.projector_width != p.projector_height)
    m.fail(key, "gives a different number of periods across the " +
                    std::to_string(p.projector_width) + " columns and the " +
                    std::to_string(p.projector_height) +
                    " rows of direction both; give `frequencies` (periods across each axis) "
                    "or one pattern per direction");
  return p.direction == pipeline::Direction::kVertical ? p.projector_height : p.projector_width;
}

// `frequencies` (periods across the encoded axis) or `pitches_px` (period
// in projector px, any positive number): exactly one. Returns the key used.
std::string frequencies(const YamlMap& m, PatternSpec& p) {
  const bool by_periods = m.has("frequencies"), by_pitch = m.has("pitches_px");
  if (by_periods == by_pitch)
    m.fail(by_periods ? "pitches_px" : "frequencies",
           "give exactly one of 'frequencies' (periods across the projector axis) or "
           "'pitches_px' (fringe period in projector px)");
  const char* key = by_periods ? "frequencies" : "pitches_px";
  const auto values = m.get<std::vector<double>>(key);
  if (values.empty()) m.fail(key, "must not be empty");
  for (double v : values)
    if (!(v > 0 && std::isfinite(v))) m.fail(key, "must be positive numbers");
  if (by_periods) {
    p.frequencies = values;
  } else {
    const int axis = pitchAxis(m, p, key);
    p.frequencies.clear();
    for (double pitch : values) p.frequencies.push_back(axis / pitch);
  }
  return key;
}

// The YAML key of a PatternSpec field (PatternSpecError::field).
std::string keyOfField(const std::string& field, const std::string& frequency_key,
                       const std::string& order_key) {
  if (field == "projector size") return "projector";
  if (field == "start_phase") return "start_phase_deg";
  if (field == "offset/amplitude") return "amplitude";
  if (field == "frequencies") return frequency_key;
  if (field == "frame_order") return order_key;
  if (field == "carrier_pitch") return "carrier_pitch_px";
  if (field == "further_phases") return "further_phases_deg";
  return field;  // steps, shift_sign, bits, reference_frames
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
  std::string frequency_key = "family";  // key blamed for the frequencies
  if (family == "phase_shift_3+3") {
    // The paper's 3+3: 3 steps at `fringes` periods (any positive number) or
    // a fine period of `pitch_px`, then 3 at unit frequency.
    p.family = PatternFamily::kPhaseShift;
    p.steps = 3;
    if (m.has("fringes") && m.has("pitch_px"))
      m.fail("pitch_px", "give one of 'fringes' (periods across the projector) or 'pitch_px'");
    if (m.has("pitch_px")) {
      const double pitch = m.get<double>("pitch_px");
      if (!(pitch > 0 && std::isfinite(pitch))) m.fail("pitch_px", "must be > 0");
      p.frequencies = {pitchAxis(m, p, "pitch_px") / pitch, 1.0};
      frequency_key = "pitch_px";
    } else {
      const double fringes = m.get<double>("fringes", 16.0);
      if (!(fringes > 0 && std::isfinite(fringes))) m.fail("fringes", "must be > 0");
      p.frequencies = {fringes, 1.0};
      frequency_key = "fringes";
    }
  } else {
    try {
      p.family = pipeline::patternFamilyFromString(family);
    } catch (const std::invalid_argument& e) {
      m.fail("family", e.what());
    }
    switch (p.family) {
      case PatternFamily::kPhaseShift:
        p.steps = m.get<int>("steps", 3);
        frequency_key = frequencies(m, p);
        try {
          p.unwrapping = pipeline::unwrappingFromString(
              m.get<std::string>("unwrapping", "hierarchical"));
        } catch (const std::invalid_argument& e) {
          m.fail("unwrapping", e.what());
        }
        parseSinusoid(m, p);
        break;
      case PatternFamily::kTwoPlusOne:
        frequency_key = frequencies(m, p);
        parseSinusoid(m, p);
        break;
      case PatternFamily::kGrayCode:
        parseGray(m, p);
        break;
      case PatternFamily::kGrayPhaseShift:
        p.steps = m.get<int>("steps", 4);
        parseGray(m, p);
        p.complementary = m.get<bool>("complementary", p.complementary);
        parseSinusoid(m, p);
        break;
      case PatternFamily::kMicroPhaseShift:
        p.steps = m.get<int>("steps", 3);
        frequency_key = frequencies(m, p);
        parseSinusoid(m, p);
        // The shift of each further frequency's frame (degrees), default
        // start_phase_deg.
        for (double deg : m.get<std::vector<double>>("further_phases_deg", {}))
          p.further_phases_rad.push_back(deg * std::numbers::pi / 180.0);
        break;
      case PatternFamily::kModulatedPhaseShift:
        p.steps = m.get<int>("steps", 3);
        frequency_key = frequencies(m, p);
        p.carrier_pitch_px = m.get<double>("carrier_pitch_px", p.carrier_pitch_px);
        parseSinusoid(m, p);
        if (m.has("modulated_sets")) {
          // One true/false per frequency: with the carrier or without.
          const YAML::Node list = m.raw("modulated_sets");
          if (!list.IsSequence())
            m.fail("modulated_sets", "must be a list of true/false, one per frequency");
          for (const YAML::Node& item : list) {
            try {
              p.modulated_sets.push_back(item.as<bool>());
            } catch (const YAML::Exception&) {
              m.fail("modulated_sets", "must be a list of true/false, one per frequency");
            }
          }
        }
        break;
    }
  }
  // The capture layout: `frame_order` (canonical frame per captured frame,
  // -1 = not part of the code) or `skip_frames` (captured frames that are
  // not part of the code, the others in canonical order).
  std::string order_key = "frame_order";
  if (m.has("frame_order") && m.has("skip_frames"))
    m.fail("skip_frames", "give one of 'frame_order' and 'skip_frames' (frame_order marks "
                          "skipped frames with -1)");
  if (m.has("frame_order")) {
    for (double v : m.get<std::vector<double>>("frame_order")) {
      if (v != std::floor(v) || v < -1)
        m.fail("frame_order", "must list canonical frame indices (integers >= 0, -1 = skip)");
      p.frame_order.push_back(static_cast<int>(v));
    }
  } else if (m.has("skip_frames")) {
    order_key = "skip_frames";
    std::vector<int> skip;
    for (double v : m.get<std::vector<double>>("skip_frames")) {
      if (v != std::floor(v) || v < 0)
        m.fail("skip_frames", "must list captured frame indices (integers >= 0)");
      skip.push_back(static_cast<int>(v));
    }
    std::sort(skip.begin(), skip.end());
    if (std::adjacent_find(skip.begin(), skip.end()) != skip.end())
      m.fail("skip_frames", "lists a frame twice");
    const int total = p.codeFrameCount() + static_cast<int>(skip.size());
    if (!skip.empty() && skip.back() >= total)
      m.fail("skip_frames", "frame " + std::to_string(skip.back()) + " is beyond the " +
                                std::to_string(total) + " captured frames (" +
                                std::to_string(p.codeFrameCount()) + " of the code + " +
                                std::to_string(skip.size()) + " skipped)");
    for (int i = 0, next = 0; i < total; ++i)
      p.frame_order.push_back(std::binary_search(skip.begin(), skip.end(), i) ? pipeline::kSkippedFrame
                                                                             : next++);
  }
  try {
    p.validate();
  } catch (const pipeline::PatternSpecError& e) {
    m.fail(keyOfField(e.field, frequency_key, order_key), e.what());
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

namespace {

std::string number(double v, int digits) {
  char text[40];
  std::snprintf(text, sizeof text, "%.*g", digits, v);
  return text;
}

std::string numbers(const std::vector<double>& values, int digits) {
  std::string out = "[";
  for (std::size_t i = 0; i < values.size(); ++i)
    out += (i ? ", " : "") + number(values[i], digits);
  return out + "]";
}

const char* boolean(bool v) { return v ? "true" : "false"; }

// The keys of `p` that describe its projected sequence (not its name), in
// pattern-file order, values as YAML flow text.
std::vector<std::pair<std::string, std::string>> patternKeys(const PatternSpec& p, int digits) {
  std::vector<std::pair<std::string, std::string>> keys;
  keys.emplace_back("family", pipeline::toString(p.family));
  keys.emplace_back("direction", pipeline::toString(p.direction));
  keys.emplace_back("projector", "{width: " + std::to_string(p.projector_width) +
                                     ", height: " + std::to_string(p.projector_height) + "}");
  const bool sinusoid = p.family != PatternFamily::kGrayCode;
  const bool gray = p.family == PatternFamily::kGrayCode || p.family == PatternFamily::kGrayPhaseShift;
  if (sinusoid && p.family != PatternFamily::kTwoPlusOne)
    keys.emplace_back("steps", std::to_string(p.steps));
  if (sinusoid && !gray) keys.emplace_back("frequencies", numbers(p.frequencies, digits));
  if (p.family == PatternFamily::kPhaseShift)
    keys.emplace_back("unwrapping", pipeline::toString(p.unwrapping));
  if (p.family == PatternFamily::kModulatedPhaseShift) {
    keys.emplace_back("carrier_pitch_px", number(p.carrier_pitch_px, digits));
    if (!p.modulated_sets.empty()) {
      std::string list = "[";
      for (std::size_t j = 0; j < p.modulated_sets.size(); ++j)
        list += std::string(j ? ", " : "") + boolean(p.modulated_sets[j]);
      keys.emplace_back("modulated_sets", list + "]");
    }
  }
  if (p.family == PatternFamily::kMicroPhaseShift && !p.further_phases_rad.empty()) {
    std::vector<double> deg;
    for (double rad : p.further_phases_rad) deg.push_back(rad * 180.0 / std::numbers::pi);
    keys.emplace_back("further_phases_deg", numbers(deg, digits));
  }
  if (gray) {
    if (p.gray_pitch_px > 0) keys.emplace_back("pitch_px", number(p.gray_pitch_px, digits));
    else keys.emplace_back("bits", std::to_string(p.gray_bits));
    keys.emplace_back("inverse", boolean(p.gray_inverse));
    keys.emplace_back("reference_frames", boolean(p.reference_frames));
  }
  if (p.family == PatternFamily::kGrayPhaseShift)
    keys.emplace_back("complementary", boolean(p.complementary));
  if (sinusoid) {
    keys.emplace_back("shift_sign", std::to_string(p.shift_sign));
    keys.emplace_back("start_phase_deg", number(p.start_phase_rad * 180.0 / std::numbers::pi, digits));
    keys.emplace_back("offset", number(p.offset, digits));
    keys.emplace_back("amplitude", number(p.amplitude, digits));
  }
  if (!p.frame_order.empty()) {
    std::vector<double> order(p.frame_order.begin(), p.frame_order.end());
    keys.emplace_back("frame_order", numbers(order, digits));
  }
  return keys;
}

}  // namespace

std::string patternYaml(const PatternSpec& spec) {
  YAML::Emitter name;
  name << spec.name;  // quoted when the name needs it
  std::string text = "# " + std::to_string(spec.frameCount()) + " frames\nname: " +
                     name.c_str() + "\n";
  for (const auto& [key, value] : patternKeys(spec, 17)) text += key + ": " + value + "\n";
  return text;
}

std::vector<std::string> patternDifferences(const PatternSpec& a, const PatternSpec& b) {
  std::vector<std::string> out;
  if (a.frameCount() != b.frameCount())
    out.push_back("frames: " + std::to_string(a.frameCount()) + " vs " +
                  std::to_string(b.frameCount()));
  const auto ka = patternKeys(a, 9), kb = patternKeys(b, 9);
  auto find = [](const auto& keys, const std::string& key) -> std::string {
    for (const auto& [k, v] : keys)
      if (k == key) return v;
    return "(none)";
  };
  for (const auto& [key, value] : ka)
    if (find(kb, key) != value) out.push_back(key + ": " + value + " vs " + find(kb, key));
  for (const auto& [key, value] : kb)
    if (find(ka, key) == "(none)") out.push_back(key + ": (none) vs " + value);
  return out;
}

PatternSpec loadPattern(const std::string& path) {
  return parsePatternText(readFile(path), path, std::filesystem::path(path).stem().string());
}

}  // namespace sl::files
