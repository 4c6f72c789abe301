// The samples the daemon's DDS edge writes, built from pipeline and engine
// values (private to daemon/). Pure: no DDS entity is touched, so every
// field is testable without DDS (tests/daemon/test_messages.cpp).
//
// Each class holds one sample and the storage its pointers refer to
// (strings, sequences converted here). Buffers named "borrowed" in a
// constructor stay the caller's and must outlive the message: the sequences
// point into them (_release = false), Cyclone serializes them in dds_write
// and never frees them. Since a sample points into its own object, the
// classes are neither copyable nor movable.
//
// Units and frames: clouds and depth in metres, the camera's optical frame
// (x right, y down, z forward); projector maps in projector px; stamps are
// the system-clock times of the pipeline values.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "depth_rectify.h"
#include "msg_convert.h"
#include "reader_acks.h"  // MatchedReaderState
#include "request_guard.h"  // RequestCounters
#include "sl/dds/cloud_layout.h"
#include "sl/daemon/scan_engine.h"  // EngineStatus
#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/types.h"

namespace sl::daemon::msg {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::dds::PackedCloud;
using ::sl::client::ScanState;

// Base of the messages below: their samples point into them.
class NonMovable {
 public:
  NonMovable() = default;
  NonMovable(const NonMovable&) = delete;
  NonMovable& operator=(const NonMovable&) = delete;
};

// sensor_msgs/PointCloud2: fields x, y, z, intensity (float32, offsets 0, 4,
// 8, 12; 16 bytes a point), then, when `packed` has them, normal_x,
// normal_y, normal_z and confidence (float32 each, following on in this
// order: PCL's and Open3D's names), little endian. `packed` is borrowed.
class CloudMessage : NonMovable {
 public:
  CloudMessage(const PackedCloud& packed, pipeline::TimestampNs stamp_ns, std::string frame_id);
  const PointCloud2& sample() const { return msg_; }

 private:
  std::string frame_id_;
  PointField fields_[8];
  PointCloud2 msg_{};
};

// sl_msgs/ProjectorMaps: up, vp, modulation (float32, NaN where a map is
// missing) and status (PixelStatus bytes), row-major, camera-sized.
class MapsMessage : NonMovable {
 public:
  MapsMessage(const pipeline::ProjectorMaps& maps, std::string pattern, std::uint64_t scan_index,
              std::string frame_id);
  const Maps& sample() const { return msg_; }

 private:
  std::string frame_id_, pattern_;
  std::vector<float> up_, vp_, modulation_;
  cv::Mat status_;  // continuous; shares the maps' buffer when it was
  Maps msg_{};
};

// The depth image (32FC1, metres, NaN where invalid: the ROS depth image
// convention) and the shading image (mono8: the fringe offset A scaled from
// the camera's `bit_depth` to 8 bits, 0 where invalid) of one cloud.
// `cloud_unit_m`: metres per unit of the cloud's coordinates.
class ScanImages : NonMovable {
 public:
  ScanImages(const pipeline::PointCloud& cloud, double cloud_unit_m, int bit_depth, std::string frame_id);
  const Image& depth() const { return depth_msg_; }
  const Image& shading() const { return shading_msg_; }
  const std::vector<float>& depthValues() const { return depth_; }  // row-major, metres

 private:
  std::string frame_id_, depth_encoding_ = "32FC1", shading_encoding_ = "mono8";
  std::vector<float> depth_;
  std::vector<std::uint8_t> shading_;
  Image depth_msg_{}, shading_msg_{};
};

// sensor_msgs/CameraInfo of a pinhole camera: plumb_bob distortion, K and P
// from its intrinsics (pixels), R the identity. The rectified image of the
// camera (DepthRectifier) has the same K and no distortion, so P = [K | 0]
// describes it (ROS's convention: P is the projection of the rectified
// image). `rectified`: the camera_info of that rectified image, D = 0.
class CameraInfoMessage : NonMovable {
 public:
  CameraInfoMessage(const pipeline::PinholeModel& camera, pipeline::TimestampNs stamp_ns,
                    std::string frame_id, bool rectified = false);
  const CameraInfo& sample() const { return msg_; }

 private:
  std::string frame_id_, model_ = "plumb_bob";
  std::vector<double> d_;
  CameraInfo msg_{};
};

// The depth image (32FC1, metres, NaN where invalid) on the camera's
// rectified grid: `raw_depth` (ScanImages::depthValues()) resampled by
// `rectifier`, whose camera must have the raw image's size.
class RectifiedDepthMessage : NonMovable {
 public:
  RectifiedDepthMessage(const std::vector<float>& raw_depth, const DepthRectifier& rectifier,
                        pipeline::TimestampNs stamp_ns, std::string frame_id);
  const Image& sample() const { return msg_; }

 private:
  std::string frame_id_, encoding_ = "32FC1";
  std::vector<float> depth_;
  Image msg_{};
};

// A copy of a sensor_msgs/Image that owns its pixels and strings, for a
// message built later on another thread (the compressed images).
class OwnedImage : NonMovable {
 public:
  explicit OwnedImage(const Image& image);
  const Image& sample() const { return msg_; }

 private:
  std::string frame_id_, encoding_;
  std::vector<std::uint8_t> pixels_;
  Image msg_{};
};

// sensor_msgs/CompressedImage of a mono8 or mono16 `image` as
// image_transport's compressed plugin writes it in png mode
// (compressed_image_transport: format "<encoding>; png compressed ", data a
// PNG of the image). `png_level`: zlib level 0..9. Throws
// std::invalid_argument for another encoding.
class CompressedPngMessage : NonMovable {
 public:
  CompressedPngMessage(const Image& image, int png_level);
  const CompressedImage& sample() const { return msg_; }

 private:
  std::string frame_id_, format_;
  std::vector<std::uint8_t> png_;
  CompressedImage msg_{};
};

// sensor_msgs/CompressedImage of a 32FC1 depth image (metres, NaN invalid)
// in image_transport's compressedDepth format, png mode
// (compressed_depth_image_transport, codec.cpp encodeCompressedDepthImage):
// format "32FC1; compressedDepth png"; data = ConfigHeader {int32 format =
// INV_DEPTH (0), float32 depthParam[2] = {A, B}} (12 bytes, little endian)
// followed by a 16-bit grey PNG of the inverse depth q = A / z + B
// (truncated), 0 where z is NaN, >= depth_max_m or too near for 16 bits; with
// A = quantization * (quantization + 1), B = 1 - A / depth_max_m. A reader
// gets z = A / (q - B). image_transport's defaults: depth_max 10 m,
// quantization 100.
class CompressedDepthMessage : NonMovable {
 public:
  static constexpr double kDepthMaxM = 10.0;
  static constexpr double kQuantization = 100.0;
  CompressedDepthMessage(const Image& depth, int png_level);
  const CompressedImage& sample() const { return msg_; }

 private:
  std::string frame_id_, format_;
  std::vector<std::uint8_t> data_;
  CompressedImage msg_{};
};

// sl_msgs/ImageSet: every image of one sequence as acquired, camera-major,
// each stamped with its exposure time and framed by `optical_frames` (one
// per camera of `set`, in its order). The frames are borrowed (copied only
// when not continuous).
class ImageSetMessage : NonMovable {
 public:
  ImageSetMessage(const pipeline::ImageSet& set, std::vector<std::string> optical_frames);
  const ImageSetMsg& sample() const { return msg_; }

 private:
  std::vector<std::string> optical_frames_, camera_ids_;
  std::vector<char*> camera_id_pointers_;
  std::vector<std::uint8_t> bit_depths_;
  std::vector<cv::Mat> continuous_;
  std::string mono8_ = "mono8", mono16_ = "mono16", pattern_, empty_;
  std::vector<Image> images_;
  ImageSetMsg msg_{};
};

// What the DDS edge itself counts, published in the status beside the
// engine's counters.
struct EdgeCounters {
  RequestCounters requests;
  std::uint64_t replies_timed_out = 0;
  std::uint64_t requests_malformed = 0;
  std::uint64_t writes_timed_out = 0;  // also counted in sets_dropped
  std::uint64_t requests_rejected = 0;       // refusals of the full request reader
  std::uint64_t clouds_lost_to_readers = 0;  // clouds at least one points reader lost
  std::uint64_t images_not_compressed = 0;   // scans whose compressed images were skipped
  std::vector<MatchedReaderState> points_readers;
};

std::uint8_t toState(ScanState s);

// sl_msgs/Status at `stamp_ns` (system clock).
class StatusMessage : NonMovable {
 public:
  StatusMessage(const EngineStatus& status, const std::vector<std::string>& patterns,
                const EdgeCounters& edge, pipeline::TimestampNs stamp_ns);
  const Status& sample() const { return msg_; }

 private:
  std::string pattern_, last_error_, recording_, degraded_, adaptive_mode_, adaptive_reason_;
  std::vector<std::string> cameras_, patterns_;
  std::vector<char*> camera_pointers_, pattern_pointers_;
  std::vector<std::string> reader_guids_;
  std::vector<PointsReader> points_readers_;
  Status msg_{};
};

// sl_msgs/CommandReply to (client_id, request_id).
class ReplyMessage : NonMovable {
 public:
  ReplyMessage(std::string client_id, std::uint64_t request_id, const CommandResult& result,
               const std::vector<std::string>& patterns, std::string detail);
  const Reply& sample() const { return msg_; }

 private:
  std::string client_id_, reason_, detail_;
  std::vector<std::string> patterns_;
  std::vector<char*> pattern_pointers_;
  Reply msg_{};
};

}  // namespace sl::daemon::msg
