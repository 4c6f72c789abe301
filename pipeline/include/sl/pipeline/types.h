// Value types passed between the pipeline stages. No threads, no DDS.
//
// Units and frames: lengths in millimetres, points in the optical frame of the
// triangulating camera (x right, y down, z forward); projector coordinates in
// projector pixels of the addressed resolution; times in nanoseconds since the
// Unix epoch (or a monotonic epoch, stated by the producer).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace sl::pipeline {

using TimestampNs = std::int64_t;

// The system (wall) clock now, in ns since the Unix epoch: the clock frames,
// trigger times and published stamps use.
TimestampNs systemClockNs();

// One camera image as delivered by a driver.
struct Frame {
  cv::Mat image;              // CV_8UC1 or CV_16UC1; owned by the frame
  TimestampNs stamp_ns = 0;   // exposure start, system clock
  std::uint64_t frame_id = 0; // the camera's frame counter
  int bit_depth = 8;          // significant bits per pixel
};

// The images of one camera for one pattern sequence, in projection order.
struct CameraImages {
  std::string camera_id;
  std::vector<cv::Mat> frames;         // CV_8UC1 or CV_16UC1, all the same size
  std::vector<TimestampNs> stamps_ns;  // exposure time of each frame
  int bit_depth = 8;                   // significant bits per pixel (8..16)
};

// All images of one pattern sequence, grouped by trigger time. Immutable once
// built: stages share it as std::shared_ptr<const ImageSet>.
struct ImageSet {
  std::uint64_t sequence_id = 0;
  std::string pattern_name;
  TimestampNs trigger_stamp_ns = 0;  // trigger time of the sequence's first pattern
  std::vector<CameraImages> cameras;
};

// Why a pixel has no projector coordinate. Stored per pixel as std::uint8_t.
enum class PixelStatus : std::uint8_t {
  kValid = 0,
  kLowModulation = 1,      // B below the threshold: shadow, dark or out of focus
  kSaturated = 2,          // a frame at the sensor's maximum value
  kUnwrapInconsistent = 3, // fringe orders from the different frequencies disagree
  kOutOfRange = 4,         // decoded coordinate outside the projector
};

// Decoded projector coordinates of one camera. All maps have the camera's size.
struct ProjectorMaps {
  std::string camera_id;
  TimestampNs stamp_ns = 0;
  cv::Mat up;          // CV_32FC1 projector column (px), NaN where invalid or not encoded
  cv::Mat vp;          // CV_32FC1 projector row (px), NaN where invalid or not encoded
  cv::Mat modulation;  // CV_32FC1 B of eq. 1 in camera DN (of the encoding frames)
  cv::Mat offset;      // CV_32FC1 A of eq. 1 in camera DN
  cv::Mat status;      // CV_8UC1 PixelStatus per pixel
  // CV_32FC1 consistency residual of the code at each pixel, the quantity the
  // codec compares with DecoderOptions::max_unwrap_error: temporal unwrapping
  // |r Phi_coarse - phi_fine - 2 pi k| / (2 pi) in periods of the finer
  // frequency (largest over the steps), Gray + phase shift with the
  // complementary bit the periods outside the half stripe, micro phase shift
  // the RMS cosine residual of the chosen period. 0 where the code has no
  // such test (Gray code, one frequency); for kBoth the larger of the two
  // directions. Any value where status is kLowModulation or kSaturated.
  cv::Mat residual;
};

struct PointXYZI {
  float x, y, z;     // mm, camera optical frame; NaN when invalid
  float intensity;   // offset A (camera DN), a shading image
};

// Organized point cloud: width x height of the camera, row-major.
struct PointCloud {
  std::string frame_id;
  TimestampNs stamp_ns = 0;
  int width = 0;
  int height = 0;
  std::vector<PointXYZI> points;

  std::size_t validCount() const;
};

}  // namespace sl::pipeline
