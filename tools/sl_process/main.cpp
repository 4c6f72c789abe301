// sl_process: decode and triangulate a recorded capture.
//
//   sl_process --pattern P.yaml --calibration C --images DIR [--out DIR]
//              [--list FILE] [--min-modulation DN] [--max-unwrap-error PERIODS]
//              [--keep-saturated] [--undistort-images] [--projector-iterations N]
//              [--use best|columns|rows] [--min-depth MM] [--max-depth MM]
//
// Frames are the image files of DIR sorted by name, or the files named one
// per line in --list (relative to DIR). Exit codes: 0 ok, 1 error, 2 usage.
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>

#include "sl/daemon/calibration_io.h"
#include "sl/daemon/pattern_config.h"
#include "sl_process/process.h"

namespace {

int usage(const std::string& message) {
  std::cerr << "sl_process: " << message << "\n"
            << "usage: sl_process --pattern P.yaml --calibration C --images DIR [--out DIR]\n"
               "         [--list FILE] [--min-modulation DN] [--max-unwrap-error PERIODS]\n"
               "         [--keep-saturated] [--undistort-images] [--projector-iterations N]\n"
               "         [--use best|columns|rows] [--min-depth MM] [--max-depth MM]\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string pattern_path, calibration_path, images_dir, out_dir = "sl_process_out", list_path;
  sl::pipeline::DecoderOptions decoder;
  sl::pipeline::TriangulatorOptions triangulator;
  bool undistort_images = false;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string arg = argv[i];
      auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
        return argv[++i];
      };
      if (arg == "--pattern") pattern_path = value();
      else if (arg == "--calibration") calibration_path = value();
      else if (arg == "--images") images_dir = value();
      else if (arg == "--out") out_dir = value();
      else if (arg == "--list") list_path = value();
      else if (arg == "--min-modulation") decoder.min_modulation = std::stof(value());
      else if (arg == "--max-unwrap-error") decoder.max_unwrap_error = std::stof(value());
      else if (arg == "--keep-saturated") decoder.reject_saturated = false;
      else if (arg == "--undistort-images") undistort_images = true;
      else if (arg == "--projector-iterations")
        triangulator.projector_distortion_iterations = std::stoi(value());
      else if (arg == "--min-depth") triangulator.min_depth_mm = std::stof(value());
      else if (arg == "--max-depth") triangulator.max_depth_mm = std::stof(value());
      else if (arg == "--use") {
        const std::string use = value();
        using Use = sl::pipeline::TriangulatorOptions::Use;
        if (use == "best") triangulator.use = Use::kBest;
        else if (use == "columns") triangulator.use = Use::kColumns;
        else if (use == "rows") triangulator.use = Use::kRows;
        else return usage("--use must be best, columns or rows");
      } else if (arg == "-h" || arg == "--help") {
        usage("help");
        return 0;
      } else {
        return usage("unknown argument '" + arg + "'");
      }
    }
  } catch (const std::exception& e) {
    return usage(e.what());
  }
  if (pattern_path.empty() || calibration_path.empty() || images_dir.empty())
    return usage("--pattern, --calibration and --images are required");

  try {
    const sl::pipeline::PatternSpec pattern = sl::daemon::loadPattern(pattern_path);
    const auto calibration = sl::daemon::loadCalibration(calibration_path).calibration;
    std::vector<std::string> files;
    if (list_path.empty()) {
      files = sl::tools::listImages(images_dir);
    } else {
      std::ifstream list(list_path);
      if (!list) throw std::runtime_error(list_path + ": cannot open list");
      for (std::string line; std::getline(list, line);) {
        if (line.empty() || line[0] == '#') continue;
        std::filesystem::path p(line);
        files.push_back((p.is_relative() ? std::filesystem::path(images_dir) / p : p).string());
      }
    }
    if (static_cast<int>(files.size()) != pattern.frameCount())
      throw std::runtime_error("pattern '" + pattern.name + "' has " +
                               std::to_string(pattern.frameCount()) + " frames, found " +
                               std::to_string(files.size()) + " images in " + images_dir);
    const sl::tools::LoadedFrames frames = sl::tools::loadFrames(files);
    const auto result =
        sl::tools::processCapture(pattern, calibration, frames, decoder, triangulator,
                                   undistort_images);
    const std::size_t points = sl::tools::writeOutputs(result, frames.bit_depth, out_dir);
    int valid = 0;
    for (int v = 0; v < result.maps.status.rows; ++v)
      for (int u = 0; u < result.maps.status.cols; ++u)
        valid += result.maps.status.at<std::uint8_t>(v, u) == 0;
    std::cout << "sl_process: " << frames.frames.size() << " frames "
              << frames.frames[0].cols << "x" << frames.frames[0].rows << ", " << valid
              << " decoded pixels, " << points << " points -> " << out_dir << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "sl_process: " << e.what() << "\n";
    return 1;
  }
}
