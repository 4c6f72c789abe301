// Board scans of the metrology tools (sl_handeye, sl_verify): a folder of one
// scan's frames -> the board's corners in the camera and the projector, as
// sl_calibrate observes them (pipeline/calibration.h observeBoard).
#pragma once

#include <functional>
#include <string>

#include "sl/pipeline/calibration.h"
#include "sl/pipeline/pattern_spec.h"

namespace sl::tools {

struct BoardScanOptions {
  pipeline::CornerDetectionOptions corners;
  pipeline::LocalHomographyOptions homographies;
};

// The command-line options both metrology tools take for their board scans:
// --board COLSxROWS, --square MM, --pattern P, --fringes N, --presmooth PX,
// --window-radius PX. Returns false when `option` is none of them; `value`
// gives the option's argument. Throws std::invalid_argument with the message
// for the user when a value is not a number of the right kind.
bool takeBoardScanOption(const std::string& option, const std::function<std::string()>& value,
                         pipeline::Checkerboard& board, std::string& pattern, int& fringes,
                         BoardScanOptions& scan);

// `value` as a finite number; throws std::invalid_argument naming `option`.
double optionNumber(const std::string& option, const std::string& value);

// `pattern`: an existing pattern file, or "3+3_both" (the built-in 3+3 with
// `fringes` periods, for the given projector size). Must code both
// directions. Throws std::runtime_error naming the pattern otherwise.
pipeline::PatternSpec boardScanPattern(const std::string& pattern, int fringes,
                                       int projector_width, int projector_height);

// Decodes the frames of `folder` (natural order of the numbers in their
// names, as many as the pattern has) and observes `board`. Throws
// std::runtime_error naming the folder when the frame count is wrong, an
// image cannot be read or the board is not found.
pipeline::BoardView observeBoardScan(const std::string& folder, const pipeline::PatternSpec& spec,
                                     const pipeline::Checkerboard& board,
                                     const BoardScanOptions& options, const std::string& label);

}  // namespace sl::tools
