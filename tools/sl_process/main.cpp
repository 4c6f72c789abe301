// sl_process: decode and triangulate a recorded capture.
//
//   sl_process --pattern P.yaml --images DIR [--calibration C [--calibration-keys K]]
//              [--out DIR] [--list FILE] [--phase] [--smooth-phase SIGMA_PX]
//              [--min-modulation DN] [--max-unwrap-error PERIODS]
//              [--keep-saturated] [--undistort-images] [--projector-iterations N]
//              [--use best|columns|rows] [--min-depth MM] [--max-depth MM]
//
// --projector-gamma / --projector-response / --estimate-gamma compensate a
// non-linear projector in decoding (pipeline/projector_response.h).
// Frames are the image files of DIR in the natural order of the numbers in
// their names (ambiguous numbering is refused), or the files named one per
// line in --list (relative to DIR). Without --calibration only the maps (and
// with --phase the phase maps) are written. The decode health of the capture
// (pipeline/decode_health.h) is printed; a recorded set folder's meta.yml is
// checked against the pattern file (name, frame count, and the set's
// pattern.yml where it has one). Exit codes: 0 ok, 1 error (including a
// capture that decodes to no valid pixel), 2 usage, or a pattern file that
// is not the recorded set's, 3 decoded but implausible (outputs written; 0
// with --accept-implausible).
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <iostream>
#include <cmath>
#include <optional>
#include <string>

#include "common/cli.h"
#include "common/frame_files.h"
#include "sl/files/calibration_io.h"
#include "sl/files/pattern_config.h"
#include "sl/pipeline/projector_response.h"
#include "sl_process/process.h"

namespace {

constexpr int kExitImplausible = 3;

const char* const kHelp =
    "usage: sl_process --pattern P.yaml --images DIR [options]\n"
    "Decodes (and with --calibration triangulates) one recorded capture.\n"
    "  --pattern FILE            pattern file describing the projected sequence (required)\n"
    "  --images DIR              folder of the frames, natural order of the numbers in their\n"
    "                            names; a recorded set's meta.yml and pattern.yml are checked\n"
    "                            against --pattern (required)\n"
    "  --list FILE               frame files one per line (relative to DIR) instead\n"
    "  --calibration FILE        camera-projector calibration: triangulate, write cloud.ply\n"
    "  --calibration-keys K      FILE.yaml or name=key,... for a calibration whose keys are\n"
    "                            not the project's (OpenCV FileStorage from other tools)\n"
    "  --out DIR                 output folder (default sl_process_out)\n"
    "  --phase                   also write the phase maps of the finest sinusoid\n"
    "  --smooth-phase SIGMA_PX   Gaussian smoothing of the decoded coordinates (camera px)\n"
    "  --min-modulation DN       modulation threshold, 8-bit DN (default: from the pattern)\n"
    "  --max-unwrap-error P      unwrapping consistency bound, periods (default 0.3)\n"
    "  --keep-saturated          decode pixels with a saturated frame too\n"
    "  --undistort-images        resample the frames onto the ideal pinhole camera first\n"
    "  --projector-iterations N  projector distortion iterations in triangulation\n"
    "  --use best|columns|rows   which projector coordinate triangulates\n"
    "  --min-depth MM            drop points nearer than this\n"
    "  --max-depth MM            drop points farther than this\n"
    "  --projector-gamma G       compensate a projector gamma in decoding\n"
    "  --projector-response FILE compensate a measured projector response\n"
    "  --estimate-gamma          estimate the projector gamma from the frames\n"
    "  --quality                 per-point quality (docs/metrology.md): confidence (expected\n"
    "                            depth sigma, mm) and nx ny nz in cloud.ply, depth_sigma.tiff\n"
    "  --camera-gain K           camera shot noise, variance K * signal (8-bit DN^2 per DN;\n"
    "                            default 0.0084, the simulator's)\n"
    "  --camera-read-noise DN    camera read noise std, 8-bit DN (default 0.05)\n"
    "  --camera-bits N           significant bits of the images for --quality (default: 8 for\n"
    "                            8-bit images, 16 for 16-bit ones; 10 or 12 for Mono10/12\n"
    "                            stored in 16-bit files)\n"
    "  --normal-step PX          normals from neighbours PX pixels away (default 3)\n"
    "  --accept-implausible      exit 0 even when the decode health says the pattern file\n"
    "                            does not fit the frames (docs/decode-health.md)\n"
    "  -h, --help                this text\n"
    "Exit codes: 0 ok, 1 error, 2 usage or a pattern file that is not the recorded set's\n"
    "(meta.yml, pattern.yml), 3 decoded but implausible.\n";

int usage(const std::string& message) {
  std::cerr << "sl_process: " << message << "\n" << kHelp;
  return 2;
}

double number(const std::string& option, const std::string& text) {
  if (const auto v = sl::tools::toNumber(text)) return *v;
  throw std::invalid_argument(option + ": expected a number, got '" + text + "'");
}

}  // namespace

int main(int argc, char** argv) {
  std::string pattern_path, calibration_path, calibration_keys, images_dir,
      out_dir = "sl_process_out", list_path;
  sl::pipeline::DecoderOptions decoder;
  sl::pipeline::TriangulatorOptions triangulator;
  bool undistort_images = false, phase = false, estimate_gamma = false, gamma_given = false,
       accept_implausible = false;
  std::string response_path;
  double smooth_sigma = 0;
  bool quality = false;
  sl::pipeline::CameraNoise noise;
  int normal_step = 3, camera_bits = 0;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string arg = argv[i];
      auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
        return argv[++i];
      };
      if (arg == "--pattern") pattern_path = value();
      else if (arg == "--calibration") calibration_path = value();
      else if (arg == "--calibration-keys") calibration_keys = value();
      else if (arg == "--images") images_dir = value();
      else if (arg == "--out") out_dir = value();
      else if (arg == "--list") list_path = value();
      else if (arg == "--phase") phase = true;
      else if (arg == "--quality") quality = true;
      else if (arg == "--camera-gain") {
        noise.gain_dn_per_electron = number(arg, value());
        if (!(noise.gain_dn_per_electron >= 0)) return usage("--camera-gain must be >= 0");
      } else if (arg == "--camera-read-noise") {
        noise.read_noise_dn = number(arg, value());
        if (!(noise.read_noise_dn >= 0)) return usage("--camera-read-noise must be >= 0");
      } else if (arg == "--camera-bits") {
        const double bits = number(arg, value());
        if (!(bits >= 8 && bits <= 16 && bits == std::floor(bits)))
          return usage("--camera-bits must be an integer 8..16");
        camera_bits = static_cast<int>(bits);
      } else if (arg == "--normal-step") {
        const double step = number(arg, value());
        if (!(step >= 1 && step <= 50 && step == std::floor(step)))
          return usage("--normal-step must be an integer 1..50 (camera px)");
        normal_step = static_cast<int>(step);
      }
      else if (arg == "--projector-gamma") {
        const double gamma = number(arg, value());
        if (!(gamma > 0)) return usage("--projector-gamma must be > 0");
        decoder.projector_response = sl::pipeline::gammaResponse(gamma);
        gamma_given = true;
      } else if (arg == "--projector-response") response_path = value();
      else if (arg == "--estimate-gamma") estimate_gamma = true;
      else if (arg == "--smooth-phase") {
        smooth_sigma = number(arg, value());
        if (!(smooth_sigma > 0)) return usage("--smooth-phase: sigma must be > 0 (camera px)");
      } else if (arg == "--min-modulation") decoder.min_modulation = static_cast<float>(number(arg, value()));
      else if (arg == "--max-unwrap-error") decoder.max_unwrap_error = static_cast<float>(number(arg, value()));
      else if (arg == "--keep-saturated") decoder.reject_saturated = false;
      else if (arg == "--undistort-images") undistort_images = true;
      else if (arg == "--projector-iterations")
        triangulator.projector_distortion_iterations = static_cast<int>(number(arg, value()));
      else if (arg == "--min-depth") triangulator.min_depth_mm = static_cast<float>(number(arg, value()));
      else if (arg == "--max-depth") triangulator.max_depth_mm = static_cast<float>(number(arg, value()));
      else if (arg == "--use") {
        const std::string use = value();
        using Use = sl::pipeline::TriangulatorOptions::Use;
        if (use == "best") triangulator.use = Use::kBest;
        else if (use == "columns") triangulator.use = Use::kColumns;
        else if (use == "rows") triangulator.use = Use::kRows;
        else return usage("--use must be best, columns or rows");
      } else if (arg == "--accept-implausible") {
        accept_implausible = true;
      } else if (arg == "-h" || arg == "--help") {
        std::cout << kHelp;
        return 0;
      } else {
        return usage("unknown argument '" + arg + "'");
      }
    }
  } catch (const std::exception& e) {
    return usage(e.what());
  }
  if (pattern_path.empty() || images_dir.empty())
    return usage("--pattern and --images are required");
  if (!calibration_keys.empty() && calibration_path.empty())
    return usage("--calibration-keys needs --calibration");
  if (calibration_path.empty() && quality) return usage("--quality needs --calibration");
  if (calibration_path.empty() && undistort_images)
    return usage("--undistort-images needs --calibration");

  try {
    const sl::pipeline::PatternSpec pattern = sl::files::loadPattern(pattern_path);
    std::optional<sl::pipeline::CameraProjectorCalibration> calibration;
    if (!calibration_path.empty() && calibration_keys.empty()) {
      try {
        calibration = sl::files::loadCalibration(calibration_path).calibration;
      } catch (const std::exception& e) {
        // A file of another tool's keys reads as one with missing keys.
        const std::string message = e.what();
        if (message.find("key '") == std::string::npos) throw;
        throw std::runtime_error(message +
                                 "; a calibration of another tool: name its keys with "
                                 "--calibration-keys (sl_process --help, docs/calibration.md)");
      }
    } else if (!calibration_path.empty())
      calibration = sl::files::loadOpenCvCalibration(
                        calibration_path, sl::files::parseOpenCvCalibrationKeys(calibration_keys))
                        .calibration;
    // Before reading any image: a pattern made for another projector, a
    // recording made with another pattern.
    if (calibration) sl::tools::checkPatternFitsCalibration(pattern, *calibration);
    if (list_path.empty()) sl::tools::checkRecordedSet(pattern, pattern_path, images_dir);
    const std::vector<std::string> files = list_path.empty()
                                               ? sl::tools::listFrameFiles(images_dir)
                                               : sl::tools::readFrameList(list_path, images_dir);
    if (static_cast<int>(files.size()) != pattern.frameCount())
      throw std::runtime_error("pattern '" + pattern.name + "' has " +
                               std::to_string(pattern.frameCount()) + " frames, found " +
                               std::to_string(files.size()) + " images in " +
                               (list_path.empty() ? images_dir : list_path));
    const sl::tools::LoadedFrames frames = sl::tools::loadFrames(files);
    if (int(estimate_gamma) + int(!response_path.empty()) + int(gamma_given) > 1)
      throw std::invalid_argument("give one of --projector-gamma, --projector-response and "
                                  "--estimate-gamma");
    if (!response_path.empty())
      decoder.projector_response = sl::files::loadProjectorResponse(response_path);
    if (estimate_gamma) {
      const auto e = sl::pipeline::estimateProjectorGamma(pattern, frames.frames, frames.bit_depth);
      std::cout << "sl_process: projector gamma " << e.gamma << " estimated from " << e.pixels
                << " pixels (unwrapping residual " << e.rms_residual_periods
                << " periods RMS, " << e.rms_residual_linear_periods << " if linear)\n";
      decoder.projector_response = sl::pipeline::gammaResponse(e.gamma);
    }
    sl::tools::ProcessResult result;
    if (calibration) {
      result = sl::tools::processCapture(pattern, *calibration, frames, decoder, triangulator,
                                         undistort_images, smooth_sigma);
    } else {
      result.maps = sl::tools::decodeCapture(pattern, frames, decoder, &result.health);
      sl::tools::smoothProjectorCoordinates(result.maps, smooth_sigma);
    }
    if (quality) {
      // The maps' DN are the images' values: their significant bits set the
      // scale of the noise model's 8-bit DN.
      if (camera_bits > frames.bit_depth)
        throw std::invalid_argument("--camera-bits " + std::to_string(camera_bits) + ": the images are " +
                                    std::to_string(frames.bit_depth) + "-bit");
      noise.bit_depth = camera_bits > 0 ? camera_bits : frames.bit_depth;
      sl::tools::addPointQuality(result, pattern, *calibration, noise, triangulator.use,
                                 normal_step);
    }
    const std::size_t points =
        sl::tools::writeOutputs(result, frames.bit_depth, out_dir, phase ? &pattern : nullptr);
    int counts[5] = {0, 0, 0, 0, 0};
    for (int v = 0; v < result.maps.status.rows; ++v)
      for (int u = 0; u < result.maps.status.cols; ++u)
        ++counts[std::min<int>(result.maps.status.at<std::uint8_t>(v, u), 4)];
    std::cout << "sl_process: " << frames.frames.size() << " frames "
              << frames.frames[0].cols << "x" << frames.frames[0].rows << " ("
              << std::filesystem::path(files.front()).filename().string() << " .. "
              << std::filesystem::path(files.back()).filename().string() << "), " << counts[0]
              << " decoded pixels";
    if (calibration) std::cout << ", " << points << " points";
    std::cout << " -> " << out_dir << "\n";
    std::cout << sl::pipeline::describeDecodeHealth(result.health, "sl_process: health: ");
    if (counts[0] == 0 || (calibration && points == 0)) {
      std::cerr << "sl_process: no " << (counts[0] == 0 ? "valid pixel" : "point")
                << " (pixels: " << counts[1] << " low modulation, " << counts[2]
                << " saturated, " << counts[3] << " unwrap inconsistent, " << counts[4]
                << " out of range" << (counts[0] > 0 ? "; every decoded pixel outside the depth "
                                                       "range or behind the camera"
                                                     : "")
                << "): check the pattern file, the frame order and the thresholds\n";
      return 1;
    }
    if (result.health.implausible) {
      std::cerr << "sl_process: decoded, but implausible for pattern '" << pattern.name
                << "' (" << pattern_path << ")";
      for (const std::string& p : result.health.problems) std::cerr << "; " << p;
      std::cerr << (accept_implausible ? " (accepted: --accept-implausible)\n"
                                       : "; outputs written; --accept-implausible to exit 0\n");
      if (!accept_implausible) return kExitImplausible;
    }
    return 0;
  } catch (const sl::tools::RecordingMismatch& e) {
    std::cerr << "sl_process: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "sl_process: " << e.what() << "\n";
    return 1;
  }
}
