// Device forms of projector images, for the TI LightCrafter 4500 (DLPC350,
// DLP4500 diamond-pixel DMD). Pure functions, thread-safe.
#pragma once

#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/camera_model.h"

namespace sl::pipeline {

// Addressed image (CV_8UC1, rows x 2*C, e.g. 1140 x 1824) -> native DMD image
// (rows x C, 912 x 1140). The DLP4500's mirrors form a diamond lattice: each
// row has C mirrors and odd rows sit half a mirror to the right, so mirror
// (row r, column c) shows addressed column 2c + (r mod 2). Throws
// std::invalid_argument for an odd width or a wrong type.
cv::Mat diamondDownsample(const cv::Mat& addressed);

// Pre-distorts an addressed image for the projector lens: output pixel q shows
// the input at the ideal (undistorted) pixel of q's ray, bilinearly
// interpolated, so that the projected image is free of lens distortion and
// decoded coordinates are undistorted projector px (triangulate them with
// projector_distortion_iterations = 0). Pixels whose ideal position falls
// outside the input are black. `projector` must have the image's size.
cv::Mat predistort(const cv::Mat& image, const PinholeModel& projector);

// Packs 8-bit patterns (CV_8UC1, all one size) three per 24-bit image as the
// LightCrafter 4500 reads them from flash or video: pattern 3k -> green
// (bit planes G0-G7, the DLPC350's pattern index 0 of an image), 3k+1 -> red
// (index 1), 3k+2 -> blue (index 2). Returns CV_8UC3 in OpenCV's BGR order
// (written to a 24-bit BMP as B, G, R bytes per pixel). Missing channels of
// the last image are black.
std::vector<cv::Mat> packRgb24(const std::vector<cv::Mat>& patterns);

}  // namespace sl::pipeline
