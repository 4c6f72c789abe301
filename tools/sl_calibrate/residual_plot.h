// Scatter plots of calibration residuals (PNG, OpenCV drawing).
#pragma once

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/calibration.h"

namespace sl::tools {

// A square scatter plot of the residuals (measured - reprojected, px) of one
// device, one colour per pose with a legend, a dashed circle at `warning_px`
// and the axis range chosen to hold every point. `projector` selects the
// projector's residuals instead of the camera's.
cv::Mat plotResiduals(const pipeline::CalibrationReport& report, bool projector,
                      double warning_px, const std::string& title);

}  // namespace sl::tools
