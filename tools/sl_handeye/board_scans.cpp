#include "board_scans.h"

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "common/frame_files.h"
#include "sl/files/pattern_config.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/pattern.h"

namespace sl::tools {

double optionNumber(const std::string& option, const std::string& value) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != value.size() || !std::isfinite(v))
    throw std::invalid_argument(option + ": expected a number, got '" + value + "'");
  return v;
}

bool takeBoardScanOption(const std::string& o, const std::function<std::string()>& value,
                         pipeline::Checkerboard& board, std::string& pattern, int& fringes,
                         BoardScanOptions& scan) {
  if (o == "--board") {
    const std::string v = value();
    const auto x = v.find('x');
    if (x == std::string::npos) throw std::invalid_argument("--board: expected COLSxROWS, got '" + v + "'");
    board.cols = static_cast<int>(optionNumber(o, v.substr(0, x)));
    board.rows = static_cast<int>(optionNumber(o, v.substr(x + 1)));
  } else if (o == "--square") {
    board.square_mm = optionNumber(o, value());
  } else if (o == "--pattern") {
    pattern = value();
  } else if (o == "--fringes") {
    fringes = static_cast<int>(optionNumber(o, value()));
  } else if (o == "--presmooth") {
    scan.corners.presmooth_sigma_px = optionNumber(o, value());
  } else if (o == "--window-radius") {
    scan.homographies.window_radius_px = static_cast<int>(optionNumber(o, value()));
  } else {
    return false;
  }
  return true;
}

pipeline::PatternSpec boardScanPattern(const std::string& pattern, int fringes,
                                       int projector_width, int projector_height) {
  pipeline::PatternSpec spec;
  if (std::filesystem::exists(pattern)) {
    spec = sl::files::loadPattern(pattern);
  } else if (pattern == "3+3_both") {
    pipeline::PhaseShift33Pattern p;
    p.name = pattern;
    p.direction = pipeline::Direction::kBoth;
    p.fringes = fringes;
    p.projector_width = projector_width;
    p.projector_height = projector_height;
    spec = pipeline::toSpec(p);
  } else {
    throw std::runtime_error("--pattern: '" + pattern +
                             "' is neither a pattern file nor the built-in 3+3_both");
  }
  if (spec.direction != pipeline::Direction::kBoth)
    throw std::runtime_error("pattern '" + spec.name +
                             "' must code both directions (local homographies need both)");
  return spec;
}

pipeline::BoardView observeBoardScan(const std::string& folder, const pipeline::PatternSpec& spec,
                                     const pipeline::Checkerboard& board,
                                     const BoardScanOptions& options, const std::string& label) {
  const std::vector<std::string> files = listFrameFiles(folder);
  if (static_cast<int>(files.size()) != spec.frameCount())
    throw std::runtime_error(folder + ": " + std::to_string(files.size()) + " images, pattern '" +
                             spec.name + "' has " + std::to_string(spec.frameCount()) + " frames");
  std::vector<cv::Mat> frames, code_frames;
  for (std::size_t k = 0; k < files.size(); ++k) {
    cv::Mat image = cv::imread(files[k], cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw std::runtime_error(files[k] + ": cannot read the image");
    if (!frames.empty() && (image.size() != frames[0].size() || image.type() != frames[0].type()))
      throw std::runtime_error(files[k] + ": size or depth differs from " + files[0]);
    frames.push_back(image);
    if (spec.frame_order.empty() || spec.frame_order[k] != pipeline::kSkippedFrame)
      code_frames.push_back(image);
  }
  const int bit_depth = frames.front().depth() == CV_8U ? 8 : 16;
  const pipeline::Decoder decoder(spec, {});
  const pipeline::ProjectorMaps maps = decoder.decode(frames, bit_depth);
  // The mean of a phase-shift sequence is a less noisy shading image than A.
  const bool mean_shading = spec.family == pipeline::PatternFamily::kPhaseShift;
  const pipeline::BoardViewResult seen =
      pipeline::observeBoard(mean_shading ? pipeline::meanImage(code_frames) : maps.offset, maps,
                             board, label, options.corners, options.homographies);
  if (!seen.view) throw std::runtime_error(folder + ": " + seen.error);
  return *seen.view;
}

}  // namespace sl::tools
