// sl_patterns: writes the projector images of a pattern file.
//
//   sl_patterns PATTERN.yaml --out DIR [--lightcrafter] [--calibration C]
//
// DIR/pattern_NN.png: 8-bit images at the addressed resolution, in
// projection order. With --calibration the images are pre-distorted for the
// projector lens of that calibration (decode them with projector distortion
// ignored). With --lightcrafter also DIR/lightcrafter4500/: diamond_NN.png
// (912 x 1140 native DMD images, see pipeline/projector_images.h) and
// image_KK.bmp (24-bit, three 8-bit patterns each: pattern 3K -> green =
// LightCrafter pattern index 0, 3K+1 -> red = index 1, 3K+2 -> blue = index 2).
// `sl_patterns --ramp N --out DIR` writes ramp_00..ramp_N.png, flat frames at
// levels k / N, to measure the projector's response (sl_calibrate
// --projector-response). Exit codes: 0 ok, 1 error, 2 usage.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "sl/files/calibration_io.h"
#include "sl/files/pattern_config.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/projector_images.h"

namespace {

const char* const kHelp =
    "usage: sl_patterns PATTERN.yaml --out DIR [--lightcrafter] [--calibration C]\n"
    "       sl_patterns --ramp N --out DIR\n"
    "Writes the projector images of a pattern file, DIR/pattern_NN.png in projection order.\n"
    "  PATTERN.yaml        the pattern file (docs/patterns-conventions.md)\n"
    "  --out DIR           output folder (required)\n"
    "  --lightcrafter      also DIR/lightcrafter4500/: native DMD images and 24-bit BMPs\n"
    "  --calibration FILE  pre-distort the images for that calibration's projector lens\n"
    "  --ramp N            instead: N + 1 flat 1824 x 1140 frames at levels k / N (2..255)\n"
    "  -h, --help          this text\n"
    "Exit codes: 0 ok, 1 error, 2 usage.\n";

int usage(const std::string& message) {
  std::cerr << "sl_patterns: " << message << "\n" << kHelp;
  return 2;
}

std::string numbered(const std::string& stem, std::size_t i, const char* ext) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "_%02zu", i);
  return stem + buf + ext;
}

void write(const std::filesystem::path& path, const cv::Mat& image) {
  if (!cv::imwrite(path.string(), image)) throw std::runtime_error(path.string() + ": cannot write");
}

}  // namespace

int main(int argc, char** argv) {
  std::string pattern_path, out_dir, calibration_path;
  bool lightcrafter = false;
  int ramp = 0;  // --ramp N: N + 1 flat frames at k / N
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--out" && i + 1 < argc) out_dir = argv[++i];
    else if (arg == "--calibration" && i + 1 < argc) calibration_path = argv[++i];
    else if (arg == "--lightcrafter") lightcrafter = true;
    else if (arg == "--ramp" && i + 1 < argc) {
      ramp = std::atoi(argv[++i]);
      if (ramp < 2 || ramp > 255) return usage("--ramp N needs N in 2..255");
    }
    else if (arg == "-h" || arg == "--help") {
      std::cout << kHelp;
      return 0;
    }
    else if (!arg.empty() && arg[0] != '-' && pattern_path.empty()) pattern_path = arg;
    else return usage("unexpected argument '" + arg + "'");
  }
  if (ramp > 0 && !out_dir.empty() && pattern_path.empty()) {
    // Flat frames at levels k / N of the default projector, for
    // sl_calibrate --projector-response.
    try {
      const std::filesystem::path dir(out_dir);
      std::filesystem::create_directories(dir);
      for (int k = 0; k <= ramp; ++k)
        write(dir / numbered("ramp", static_cast<std::size_t>(k), ".png"),
              cv::Mat(1140, 1824, CV_8UC1, cv::Scalar(std::lround(255.0 * k / ramp))));
      std::cout << "sl_patterns: " << ramp + 1 << " flat frames (levels k / " << ramp << ") -> "
                << out_dir << "\n";
      return 0;
    } catch (const std::exception& e) {
      std::cerr << "sl_patterns: " << e.what() << "\n";
      return 1;
    }
  }
  if (pattern_path.empty() || out_dir.empty()) return usage("PATTERN.yaml and --out are required");
  try {
    const sl::pipeline::PatternSpec spec = sl::files::loadPattern(pattern_path);
    std::vector<cv::Mat> images = sl::pipeline::generatePatternImages(spec);
    if (!calibration_path.empty()) {
      const auto calibration = sl::files::loadCalibration(calibration_path).calibration;
      for (cv::Mat& image : images) image = sl::pipeline::predistort(image, calibration.projector);
    }
    const std::filesystem::path dir(out_dir);
    std::filesystem::create_directories(dir);
    for (std::size_t i = 0; i < images.size(); ++i) write(dir / numbered("pattern", i, ".png"), images[i]);
    if (lightcrafter) {
      const auto lc = dir / "lightcrafter4500";
      std::filesystem::create_directories(lc);
      std::vector<cv::Mat> native;
      for (const cv::Mat& image : images) native.push_back(sl::pipeline::diamondDownsample(image));
      for (std::size_t i = 0; i < native.size(); ++i) write(lc / numbered("diamond", i, ".png"), native[i]);
      const auto packed = sl::pipeline::packRgb24(native);
      for (std::size_t i = 0; i < packed.size(); ++i) write(lc / numbered("image", i, ".bmp"), packed[i]);
    }
    std::cout << "sl_patterns: '" << spec.name << "' (" << sl::pipeline::toString(spec.family)
              << ", " << sl::pipeline::toString(spec.direction) << ", " << images.size()
              << " frames, " << spec.projector_width << "x" << spec.projector_height << ") -> "
              << out_dir << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sl_patterns: " << e.what() << "\n";
    return 1;
  }
}
