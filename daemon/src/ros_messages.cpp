#include "ros_messages.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>
#include <limits>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>

namespace sl::daemon::msg {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::dds::PackedCloud;
using ::sl::client::ScanState;
using ::sl::client::TriggerMode;
using ::sl::client::toReplyCode;

namespace {

// A sequence field borrowing `n` elements at `data`.
template <typename Seq, typename T>
void borrow(Seq& seq, T* data, std::size_t n) {
  seq._maximum = static_cast<std::uint32_t>(n);
  seq._length = static_cast<std::uint32_t>(n);
  seq._buffer = data;
  seq._release = false;
}

// char* pointers into `values` (which must not change afterwards).
std::vector<char*> pointersInto(std::vector<std::string>& values) {
  std::vector<char*> pointers;
  pointers.reserve(values.size());
  for (auto& s : values) pointers.push_back(s.data());
  return pointers;
}

// A CV_32FC1 map as rows * cols floats; NaN where the map is missing.
std::vector<float> floatsOf(const cv::Mat& m, std::size_t n) {
  std::vector<float> v(n, std::numeric_limits<float>::quiet_NaN());
  if (!m.empty()) {
    const cv::Mat continuous = m.isContinuous() ? m : m.clone();
    std::memcpy(v.data(), continuous.ptr<float>(), n * sizeof(float));
  }
  return v;
}

}  // namespace

CloudMessage::CloudMessage(const PackedCloud& packed, pipeline::TimestampNs stamp_ns,
                           std::string frame_id)
    : frame_id_(std::move(frame_id)) {
  static const char* kNames[8] = {"x",        "y",        "z",        "intensity",
                                  "normal_x", "normal_y", "normal_z", "confidence"};
  std::uint32_t n = 0;
  auto add = [&](int name) {
    fields_[n] = {const_cast<char*>(kNames[name]), 4 * n, kFloat32, 1};
    ++n;
  };
  for (int i = 0; i < 4; ++i) add(i);
  if (packed.normals)
    for (int i = 4; i < 7; ++i) add(i);
  if (packed.confidence) add(7);
  if (packed.point_step != 4 * n)
    throw std::invalid_argument("packed cloud: point_step " + std::to_string(packed.point_step) +
                                " for " + std::to_string(n) + " float32 fields");
  msg_.header.stamp = toTime(stamp_ns);
  msg_.header.frame_id = frame_id_.data();
  msg_.height = packed.height;
  msg_.width = packed.width;
  borrow(msg_.fields, fields_, n);
  msg_.is_bigendian = false;  // x86-64 / aarch64 little endian, as written
  msg_.point_step = packed.point_step;
  msg_.row_step = packed.point_step * msg_.width;
  borrow(msg_.data, const_cast<std::uint8_t*>(packed.data), packed.bytes);
  // Organized, invalid pixels are NaN points, so the cloud may hold some:
  // is_dense = false (as ROS depth drivers publish organized clouds); finding
  // out that none is invalid would cost a pass over the points.
  msg_.is_dense = packed.dense;
}

MapsMessage::MapsMessage(const pipeline::ProjectorMaps& maps, std::string pattern,
                         std::uint64_t scan_index, std::string frame_id)
    : frame_id_(std::move(frame_id)), pattern_(std::move(pattern)) {
  const int rows = maps.status.rows, cols = maps.status.cols;
  const std::size_t n = static_cast<std::size_t>(rows) * cols;
  up_ = floatsOf(maps.up, n);
  vp_ = floatsOf(maps.vp, n);
  modulation_ = floatsOf(maps.modulation, n);
  status_ = maps.status.isContinuous() ? maps.status : maps.status.clone();
  msg_.header.stamp = toTime(maps.stamp_ns);
  msg_.header.frame_id = frame_id_.data();
  msg_.pattern = pattern_.data();
  msg_.scan_index = scan_index;
  msg_.height = static_cast<std::uint32_t>(rows);
  msg_.width = static_cast<std::uint32_t>(cols);
  borrow(msg_.up, up_.data(), n);
  borrow(msg_.vp, vp_.data(), n);
  borrow(msg_.modulation, modulation_.data(), n);
  borrow(msg_.status, status_.ptr<std::uint8_t>(), n);
}

ScanImages::ScanImages(const pipeline::PointCloud& cloud, double cloud_unit_m, int bit_depth,
                       std::string frame_id)
    : frame_id_(std::move(frame_id)) {
  const std::size_t n = cloud.points.size();
  depth_.resize(n);
  shading_.resize(n);
  const float to_8bit = 255.0f / float((1 << bit_depth) - 1);
  const float to_metres = static_cast<float>(cloud_unit_m);
  for (std::size_t i = 0; i < n; ++i) {
    depth_[i] = cloud.points[i].z * to_metres;
    const float a = cloud.points[i].intensity * to_8bit;
    shading_[i] = std::isfinite(a) ? static_cast<std::uint8_t>(std::clamp(a + 0.5f, 0.0f, 255.0f)) : 0;
  }
  auto fill = [&](Image& msg, std::string& encoding, void* data, std::uint32_t bytes_per_pixel) {
    msg.header.stamp = toTime(cloud.stamp_ns);
    msg.header.frame_id = frame_id_.data();
    msg.height = static_cast<std::uint32_t>(cloud.height);
    msg.width = static_cast<std::uint32_t>(cloud.width);
    msg.encoding = encoding.data();
    msg.is_bigendian = 0;
    msg.step = msg.width * bytes_per_pixel;
    borrow(msg.data, static_cast<std::uint8_t*>(data), n * bytes_per_pixel);
  };
  fill(depth_msg_, depth_encoding_, depth_.data(), 4);
  fill(shading_msg_, shading_encoding_, shading_.data(), 1);
}

CameraInfoMessage::CameraInfoMessage(const pipeline::PinholeModel& camera, pipeline::TimestampNs stamp_ns,
                                     std::string frame_id, bool rectified)
    : frame_id_(std::move(frame_id)), d_(camera.distortion.begin(), camera.distortion.end()) {
  if (rectified) d_.assign(d_.size(), 0.0);
  msg_.header.stamp = toTime(stamp_ns);
  msg_.header.frame_id = frame_id_.data();
  msg_.height = static_cast<std::uint32_t>(camera.height);
  msg_.width = static_cast<std::uint32_t>(camera.width);
  msg_.distortion_model = model_.data();
  borrow(msg_.d, d_.data(), d_.size());
  const double k[9] = {camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1};
  std::copy(std::begin(k), std::end(k), msg_.k);
  const double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::copy(std::begin(r), std::end(r), msg_.r);
  const double p[12] = {camera.fx, 0, camera.cx, 0, 0, camera.fy, camera.cy, 0, 0, 0, 1, 0};
  std::copy(std::begin(p), std::end(p), msg_.p);
  msg_.binning_x = msg_.binning_y = 0;
  msg_.roi = {0, 0, 0, 0, false};
}

RectifiedDepthMessage::RectifiedDepthMessage(const std::vector<float>& raw_depth,
                                             const DepthRectifier& rectifier,
                                             pipeline::TimestampNs stamp_ns, std::string frame_id)
    : frame_id_(std::move(frame_id)) {
  rectifier.rectify(raw_depth, depth_);
  msg_.header.stamp = toTime(stamp_ns);
  msg_.header.frame_id = frame_id_.data();
  msg_.height = static_cast<std::uint32_t>(rectifier.height());
  msg_.width = static_cast<std::uint32_t>(rectifier.width());
  msg_.encoding = encoding_.data();
  msg_.is_bigendian = 0;
  msg_.step = msg_.width * 4;
  borrow(msg_.data, reinterpret_cast<std::uint8_t*>(depth_.data()), depth_.size() * 4);
}

OwnedImage::OwnedImage(const Image& image)
    : frame_id_(image.header.frame_id ? image.header.frame_id : ""),
      encoding_(image.encoding ? image.encoding : ""),
      pixels_(image.data._buffer, image.data._buffer + image.data._length),
      msg_(image) {
  msg_.header.frame_id = frame_id_.data();
  msg_.encoding = encoding_.data();
  borrow(msg_.data, pixels_.data(), pixels_.size());
}

CompressedPngMessage::CompressedPngMessage(const Image& image, int png_level)
    : frame_id_(image.header.frame_id ? image.header.frame_id : ""),
      format_(std::string(image.encoding ? image.encoding : "") + "; png compressed ") {
  const std::string encoding = image.encoding ? image.encoding : "";
  const int type = encoding == "mono8" ? CV_8UC1 : encoding == "mono16" ? CV_16UC1 : -1;
  if (type < 0) throw std::invalid_argument("CompressedPngMessage: encoding '" + encoding + "' is not mono8/mono16");
  const cv::Mat pixels(static_cast<int>(image.height), static_cast<int>(image.width), type,
                       image.data._buffer, image.step);
  if (!cv::imencode(".png", pixels, png_, {cv::IMWRITE_PNG_COMPRESSION, png_level}))
    throw std::runtime_error("CompressedPngMessage: PNG encoding failed");
  msg_.header.stamp = image.header.stamp;
  msg_.header.frame_id = frame_id_.data();
  msg_.format = format_.data();
  borrow(msg_.data, png_.data(), png_.size());
}

CompressedDepthMessage::CompressedDepthMessage(const Image& depth, int png_level)
    : frame_id_(depth.header.frame_id ? depth.header.frame_id : ""), format_("32FC1; compressedDepth png") {
  const std::string encoding = depth.encoding ? depth.encoding : "";
  if (encoding != "32FC1") throw std::invalid_argument("CompressedDepthMessage: encoding '" + encoding + "' is not 32FC1");
  const int rows = static_cast<int>(depth.height), cols = static_cast<int>(depth.width);
  const cv::Mat z(rows, cols, CV_32FC1, depth.data._buffer, depth.step);
  // As compressed_depth_image_transport computes them (float).
  const float depth_max = static_cast<float>(kDepthMaxM);
  const float quant_a = static_cast<float>(kQuantization) * (static_cast<float>(kQuantization) + 1.0f);
  const float quant_b = 1.0f - quant_a / depth_max;
  cv::Mat inverse(rows, cols, CV_16UC1);
  for (int r = 0; r < rows; ++r) {
    const float* in = z.ptr<float>(r);
    std::uint16_t* out = inverse.ptr<std::uint16_t>(r);
    for (int c = 0; c < cols; ++c) {
      // Depths the 16 bits cannot hold (nearer than A / (65536 - B), 0.152 m
      // with the defaults) are sent as invalid, like NaN and far ones.
      const float q = in[c] < depth_max && in[c] > 0.0f ? quant_a / in[c] + quant_b : 0.0f;
      out[c] = q < 65536.0f ? static_cast<std::uint16_t>(q) : 0;
    }
  }
  std::vector<std::uint8_t> png;
  if (!cv::imencode(".png", inverse, png, {cv::IMWRITE_PNG_COMPRESSION, png_level}))
    throw std::runtime_error("CompressedDepthMessage: PNG encoding failed");
  // ConfigHeader {compressionFormat format; float depthParam[2];}, little endian.
  const std::int32_t inv_depth = 0;
  data_.resize(12 + png.size());
  std::memcpy(data_.data(), &inv_depth, 4);
  std::memcpy(data_.data() + 4, &quant_a, 4);
  std::memcpy(data_.data() + 8, &quant_b, 4);
  std::memcpy(data_.data() + 12, png.data(), png.size());
  msg_.header.stamp = depth.header.stamp;
  msg_.header.frame_id = frame_id_.data();
  msg_.format = format_.data();
  borrow(msg_.data, data_.data(), data_.size());
}

ImageSetMessage::ImageSetMessage(const pipeline::ImageSet& set, std::vector<std::string> optical_frames)
    : optical_frames_(std::move(optical_frames)), pattern_(set.pattern_name) {
  if (optical_frames_.size() != set.cameras.size())
    throw std::invalid_argument("ImageSetMessage: one optical frame per camera expected");
  std::size_t total = 0;
  for (const auto& c : set.cameras) total += c.frames.size();
  images_.resize(total);
  continuous_.reserve(total);
  for (const auto& c : set.cameras) {
    camera_ids_.push_back(c.camera_id);
    bit_depths_.push_back(static_cast<std::uint8_t>(c.bit_depth));
  }
  camera_id_pointers_ = pointersInto(camera_ids_);
  std::size_t i = 0;
  for (std::size_t k = 0; k < set.cameras.size(); ++k) {
    const pipeline::CameraImages& c = set.cameras[k];
    for (std::size_t f = 0; f < c.frames.size(); ++f, ++i) {
      continuous_.push_back(c.frames[f].isContinuous() ? c.frames[f] : c.frames[f].clone());
      const cv::Mat& m = continuous_.back();
      Image& msg = images_[i];
      msg.header.stamp = toTime(c.stamps_ns[f]);
      msg.header.frame_id = optical_frames_[k].data();
      msg.height = static_cast<std::uint32_t>(m.rows);
      msg.width = static_cast<std::uint32_t>(m.cols);
      msg.encoding = m.elemSize() == 1 ? mono8_.data() : mono16_.data();
      msg.is_bigendian = 0;  // little endian, as in memory
      msg.step = static_cast<std::uint32_t>(m.cols * m.elemSize());
      borrow(msg.data, const_cast<std::uint8_t*>(m.ptr<std::uint8_t>()), m.total() * m.elemSize());
    }
  }
  msg_.header.stamp = toTime(set.trigger_stamp_ns);
  msg_.header.frame_id = empty_.data();
  msg_.pattern = pattern_.data();
  msg_.sequence_id = set.sequence_id;
  msg_.camera_count = static_cast<std::uint32_t>(set.cameras.size());
  borrow(msg_.camera_ids, camera_id_pointers_.data(), camera_id_pointers_.size());
  borrow(msg_.bit_depths, bit_depths_.data(), bit_depths_.size());
  borrow(msg_.images, images_.data(), images_.size());
}

std::uint8_t toState(ScanState s) {
  switch (s) {
    case ScanState::kIdle: return sl_msgs_msg_dds__Status_Constants_STATE_IDLE;
    case ScanState::kScanning: return sl_msgs_msg_dds__Status_Constants_STATE_SCANNING;
    case ScanState::kError: return sl_msgs_msg_dds__Status_Constants_STATE_ERROR;
    case ScanState::kWaiting: return sl_msgs_msg_dds__Status_Constants_STATE_WAITING;
    case ScanState::kDegraded: return sl_msgs_msg_dds__Status_Constants_STATE_DEGRADED;
  }
  return sl_msgs_msg_dds__Status_Constants_STATE_ERROR;
}

StatusMessage::StatusMessage(const EngineStatus& s, const std::vector<std::string>& patterns,
                             const EdgeCounters& edge, pipeline::TimestampNs stamp_ns)
    : pattern_(s.pattern),
      last_error_(s.last_error),
      recording_(s.recording),
      degraded_(s.degraded_reason),
      adaptive_mode_(s.adaptive_mode),
      adaptive_reason_(s.adaptive_reason),
      cameras_(s.cameras),
      patterns_(patterns),
      camera_pointers_(pointersInto(cameras_)),
      pattern_pointers_(pointersInto(patterns_)) {
  Status& msg = msg_;
  msg.stamp = toTime(stamp_ns);
  msg.state = toState(s.state);
  msg.pattern = pattern_.data();
#define SL_COPY_FIELD(type, name, label) msg.name = s.name;
  SL_STATUS_ENGINE_FIELDS(SL_COPY_FIELD)
#undef SL_COPY_FIELD
  msg.sets_dropped = s.sets_dropped + edge.writes_timed_out;
  msg.writes_timed_out = edge.writes_timed_out;
  msg.images_not_compressed = edge.images_not_compressed;
  msg.trigger = s.trigger == TriggerMode::kSoftware ? sl_msgs_msg_dds__Status_Constants_TRIGGER_SOFTWARE
                                                    : sl_msgs_msg_dds__Status_Constants_TRIGGER_HARDWARE;
  borrow(msg.cameras, camera_pointers_.data(), camera_pointers_.size());
  msg.motion_compensation = s.motion_compensation;
  msg.start_at = toTime(s.start_at_ns);
  msg.last_error = last_error_.data();
  msg.recording = recording_.data();
  borrow(msg.patterns, pattern_pointers_.data(), pattern_pointers_.size());
  msg.requests_received = edge.requests.received;
  msg.requests_answered = edge.requests.answered;
  msg.requests_rate_limited = edge.requests.rate_limited;
  msg.requests_invalid = edge.requests.invalid;
  msg.replies_timed_out = edge.replies_timed_out;
  msg.degraded_reason = degraded_.data();
  msg.last_error_stamp = toTime(s.last_error_ns);
  msg.requests_malformed = edge.requests_malformed;
  msg.requests_rejected = edge.requests_rejected;
  msg.clouds_lost_to_readers = edge.clouds_lost_to_readers;
  msg.adaptive_mode = adaptive_mode_.data();
  msg.adaptive_reason = adaptive_reason_.data();
  for (const MatchedReaderState& r : edge.points_readers) reader_guids_.push_back(r.guid);
  points_readers_.resize(edge.points_readers.size());
  for (std::size_t i = 0; i < points_readers_.size(); ++i) {
    const MatchedReaderState& r = edge.points_readers[i];
    points_readers_[i] = {reader_guids_[i].data(), r.reliable, r.acknowledging, r.lost};
  }
  borrow(msg.points_readers, points_readers_.data(), points_readers_.size());
}

ReplyMessage::ReplyMessage(std::string client_id, std::uint64_t request_id, const CommandResult& result,
                           const std::vector<std::string>& patterns, std::string detail)
    : client_id_(std::move(client_id)),
      reason_(result.reason),
      detail_(std::move(detail)),
      patterns_(patterns),
      pattern_pointers_(pointersInto(patterns_)) {
  msg_.client_id = client_id_.data();
  msg_.request_id = request_id;
  msg_.accepted = result.accepted();
  msg_.code = toReplyCode(result.code);
  msg_.reason = reason_.data();
  msg_.detail = detail_.data();
  borrow(msg_.patterns, pattern_pointers_.data(), pattern_pointers_.size());
}

}  // namespace sl::daemon::msg
