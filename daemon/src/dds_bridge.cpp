#include "sl/daemon/dds_bridge.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string_view>
#include <string>
#include <vector>

#include <dds/ddsrt/log.h>
#include <opencv2/core.hpp>

#include "msg_convert.h"
#include "sl/daemon/cloud_layout.h"
#include "request_guard.h"
#include "sl/daemon/dds.h"
#include "sl/daemon/log.h"

namespace sl::daemon {

namespace {

using namespace msg;

// Sequences in the samples we write borrow our buffers (_release = false):
// Cyclone serializes during dds_write and never frees them.
template <typename Seq, typename T>
void borrow(Seq& seq, T* data, std::size_t n) {
  seq._maximum = static_cast<std::uint32_t>(n);
  seq._length = static_cast<std::uint32_t>(n);
  seq._buffer = data;
  seq._release = false;
}

// Holds the string storage that borrowed char* fields point into.
struct StringList {
  std::vector<std::string> values;
  std::vector<char*> pointers;
  explicit StringList(std::vector<std::string> v) : values(std::move(v)) {
    for (auto& s : values) pointers.push_back(s.data());
  }
};

sl_msgs_msg_State toState(ScanState s) {
  switch (s) {
    case ScanState::kIdle: return sl_msgs_msg_STATE_IDLE;
    case ScanState::kScanning: return sl_msgs_msg_STATE_SCANNING;
    case ScanState::kError: return sl_msgs_msg_STATE_ERROR;
    case ScanState::kWaiting: return sl_msgs_msg_STATE_WAITING;
    case ScanState::kDegraded: return sl_msgs_msg_STATE_DEGRADED;
  }
  return sl_msgs_msg_STATE_ERROR;
}

// The START options of a request; a value outside the IDL enums is reported
// in `error` (the request is then rejected).
StartRequest toStartRequest(const Request& request, std::string& error) {
  StartRequest r;
  r.pattern = request.pattern ? request.pattern : "";
  r.count = request.count;
  r.recording = request.recording ? request.recording : "";
  switch (request.trigger) {
    case sl_msgs_msg_TRIGGER_DEFAULT: break;
    case sl_msgs_msg_TRIGGER_HARDWARE: r.trigger = TriggerMode::kHardware; break;
    case sl_msgs_msg_TRIGGER_SOFTWARE: r.trigger = TriggerMode::kSoftware; break;
    default: error = "unknown trigger mode " + std::to_string(static_cast<int>(request.trigger));
  }
  switch (request.motion_compensation) {
    case sl_msgs_msg_MOTION_DEFAULT: break;
    case sl_msgs_msg_MOTION_ON: r.motion_compensation = true; break;
    case sl_msgs_msg_MOTION_OFF: r.motion_compensation = false; break;
    default:
      error = "unknown motion compensation value " +
              std::to_string(static_cast<int>(request.motion_compensation));
  }
  r.delay_s = request.delay_s;
  r.start_at_ns = fromTime(request.start_at);
  r.cameras = toStrings(request.cameras);
  return r;
}

// " count N" and the options that differ from the defaults, for the log.
std::string describeStart(const Request& request) {
  std::string text = " count " + std::to_string(request.count);
  if (request.trigger == sl_msgs_msg_TRIGGER_HARDWARE) text += " trigger hardware";
  if (request.trigger == sl_msgs_msg_TRIGGER_SOFTWARE) text += " trigger software";
  if (request.delay_s != 0) text += " delay " + std::to_string(request.delay_s) + " s";
  if (fromTime(request.start_at) != 0) text += " at " + std::to_string(fromTime(request.start_at)) + " ns";
  if (request.cameras._length > 0) {
    text += " cameras";
    for (const auto& id : toStrings(request.cameras)) text += " " + id;
  }
  if (request.motion_compensation == sl_msgs_msg_MOTION_ON) text += " motion on";
  if (request.motion_compensation == sl_msgs_msg_MOTION_OFF) text += " motion off";
  return text;
}

// A writer's QoS from the configuration (README "Topics").
dds::Qos writerQos(const TopicQos& q) {
  dds::Qos qos;
  if (q.reliable)
    qos.reliable(static_cast<dds_duration_t>(std::llround(q.max_blocking_s * 1e9)));
  else
    qos.bestEffort();
  return qos.keepLast(q.depth).xcdr1();
}

// Counts the requests Cyclone could not deserialize (an out-of-range enum,
// a truncated or garbled sample): its receive path drops such a sample
// before any reader sees it and only logs a warning ("deserialization
// <topic>/<type> failed"), so the count comes from its log sink, which is
// process-wide (the last bridge created owns it). Every other message goes
// to stderr as with Cyclone's default sink; of the dropped requests' lines
// the first 10 and then every 1000th are printed, so a flood of garbage
// cannot flood the log.
class MalformedSampleCounter {
 public:
  explicit MalformedSampleCounter(std::string type_name) : type_name_(std::move(type_name)) {
    dds_set_log_sink(&MalformedSampleCounter::sink, this);
  }
  ~MalformedSampleCounter() { dds_set_log_sink(nullptr, nullptr); }
  MalformedSampleCounter(const MalformedSampleCounter&) = delete;
  MalformedSampleCounter& operator=(const MalformedSampleCounter&) = delete;
  std::uint64_t count() const { return count_.load(); }

 private:
  static void sink(void* self, const dds_log_data_t* data) {
    auto* me = static_cast<MalformedSampleCounter*>(self);
    const std::string_view text(data->message, data->size);
    if (text.find("deserialization") != std::string_view::npos &&
        text.find(me->type_name_) != std::string_view::npos) {
      const std::uint64_t n = ++me->count_;
      if (n > 10 && n % 1000 != 0) return;
    }
    std::fwrite(data->message, 1, data->size, stderr);
  }
  const std::string type_name_;
  std::atomic<std::uint64_t> count_{0};
};

}  // namespace

TopicNames TopicNames::forNamespace(const std::string& ns) {
  return {"rt/" + ns + "/points", "rt/" + ns + "/projector_maps", "rt/" + ns + "/image_sets",
          "rt/" + ns + "/status", "rq/" + ns + "/commandRequest", "rr/" + ns + "/commandReply",
          "rt/" + ns + "/depth/image", "rt/" + ns + "/shading/image", "rt/" + ns + "/camera_info"};
}

std::string FrameIds::of(const std::string& camera_id) const {
  return camera_id == first_camera_id ? first_frame_id : camera_id + "_optical_frame";
}

struct DdsBridge::Impl {
  Impl(const DdsConfig& config, const std::string& camera_id, const pipeline::PinholeModel& camera)
      : config(config),
        frame_ids{camera_id, config.frame_id},
        camera(camera),
        names(TopicNames::forNamespace(config.ns)),
        participant(config.domain_id),
        points_topic(participant, names.points, sensor_msgs_msg_dds__PointCloud2__desc),
        maps_topic(participant, names.projector_maps, sl_msgs_msg_ProjectorMaps_desc),
        status_topic(participant, names.status, sl_msgs_msg_Status_desc),
        request_topic(participant, names.request, sl_msgs_msg_CommandRequest_desc),
        reply_topic(participant, names.reply, sl_msgs_msg_CommandReply_desc),
        depth_topic(participant, names.depth_image, sensor_msgs_msg_dds__Image__desc),
        shading_topic(participant, names.shading_image, sensor_msgs_msg_dds__Image__desc),
        info_topic(participant, names.camera_info, sensor_msgs_msg_dds__CameraInfo__desc),
        sets_topic(participant, names.image_sets, sl_msgs_msg_ImageSet_desc),
        // Clouds, maps, images: as configured (dds.qos; by default reliable
        // with a short keep-last history: a write waits at most
        // max_blocking_s for acknowledgements, then it is counted as timed out).
        points_writer(participant, points_topic, writerQos(config.points_qos)),
        maps_writer(participant, maps_topic, writerQos(config.maps_qos)),
        // Status: the latest value for late joiners.
        status_writer(participant, status_topic,
                      dds::Qos().reliable().transientLocal().keepLast(1).xcdr1()),
        // Requests: keep-all with a bound, so that a flood is held back by
        // the reliable protocol (the writer blocks) instead of overwriting
        // unread requests without a trace.
        request_reader(participant, request_topic,
                       dds::Qos().reliable().keepAll().resourceLimits(256, -1, -1)),
        reply_writer(participant, reply_topic, dds::Qos().reliable().keepLast(64).xcdr1()),
        depth_writer(participant, depth_topic, writerQos(config.images_qos)),
        shading_writer(participant, shading_topic, writerQos(config.images_qos)),
        info_writer(participant, info_topic, writerQos(config.images_qos)),
        sets_writer(participant, sets_topic, writerQos(config.image_sets_qos)),
        request_condition(request_reader),
        wake(participant),
        waitset(participant) {
    waitset.attach(request_condition, 1);
    waitset.attach(wake, 2);
  }

  const DdsConfig config;
  const FrameIds frame_ids;
  const pipeline::PinholeModel camera;  // of the first camera, for camera_info
  const TopicNames names;
  MalformedSampleCounter malformed{sl_msgs_msg_CommandRequest_desc.m_typename};  // before any DDS entity
  dds::Participant participant;
  dds::Topic<PointCloud2> points_topic;
  dds::Topic<Maps> maps_topic;
  dds::Topic<Status> status_topic;
  dds::Topic<Request> request_topic;
  dds::Topic<Reply> reply_topic;
  dds::Topic<Image> depth_topic;
  dds::Topic<Image> shading_topic;
  dds::Topic<CameraInfo> info_topic;
  dds::Topic<ImageSetMsg> sets_topic;
  dds::Writer<PointCloud2> points_writer;
  dds::Writer<Maps> maps_writer;
  dds::Writer<Status> status_writer;
  dds::Reader<Request> request_reader;
  dds::Writer<Reply> reply_writer;
  dds::Writer<Image> depth_writer;
  dds::Writer<Image> shading_writer;
  dds::Writer<CameraInfo> info_writer;
  dds::Writer<ImageSetMsg> sets_writer;
  dds::ReadCondition request_condition;
  dds::GuardCondition wake;
  dds::WaitSet waitset;
  std::atomic<bool> stopping{false};
  std::atomic<double> status_period_s{config.status_period_s};  // reloadable
  std::atomic<std::uint64_t> writes_timed_out{0};
  // Requests: size checks, rate limits, repeated ids, counters (request
  // loop only). Replies that could not be written within the reliable
  // writer's blocking time count separately.
  RequestGuard guard{config.requests};
  std::uint64_t replies_timed_out = 0;
  std::uint64_t rate_limited_logged = 0;

  // Publish-thread scratch buffer (metres), reused between clouds.
  std::vector<float> cloud_buffer;
  // The image set published last (a set triangulated by two cameras gives
  // two results; it is published once). Publish thread only.
  pipeline::TimestampNs last_set_stamp_ns = -1;

  void publishCloud(const pipeline::PointCloud& cloud, double unit_m, const std::string& frame_id);
  void publishMaps(const pipeline::ProjectorMaps& maps, const ScanResult& result);
  void publishImages(const ScanResult& result);
  void publishImageSet(const pipeline::ImageSet& set);
  void publishStatus(const EngineStatus& s, const std::vector<std::string>& patterns);
  void answer(ScanEngine& engine, const Request& request);
};

void DdsBridge::Impl::publishCloud(const pipeline::PointCloud& cloud, double unit_m,
                                   const std::string& frame_id_of_camera) {
  // Triangulated in metres (the engine's CloudUnit) and sent whole, the
  // cloud's points are the message's data; else one pass packs them.
  const PackedCloud packed = packCloud(cloud, unit_m, config.points_layout, cloud_buffer);
  static const char* kNames[4] = {"x", "y", "z", "intensity"};
  PointField fields[4];
  for (int i = 0; i < 4; ++i)
    fields[i] = {const_cast<char*>(kNames[i]), static_cast<std::uint32_t>(4 * i), kFloat32, 1};
  std::string frame_id = frame_id_of_camera;

  PointCloud2 msg{};
  msg.header.stamp = toTime(cloud.stamp_ns);
  msg.header.frame_id = frame_id.data();
  msg.height = packed.height;
  msg.width = packed.width;
  borrow(msg.fields, fields, 4);
  msg.is_bigendian = false;  // x86-64 / aarch64 little endian, as written
  msg.point_step = 16;
  msg.row_step = 16 * msg.width;
  borrow(msg.data, const_cast<std::uint8_t*>(packed.data), packed.bytes);
  // Organized, invalid pixels are NaN points, so the cloud may hold some:
  // is_dense = false (as ROS depth drivers publish organized clouds); finding
  // out that none is invalid would cost a pass over the points.
  msg.is_dense = packed.dense;
  if (!points_writer.write(msg)) ++writes_timed_out;
}

void DdsBridge::Impl::publishMaps(const pipeline::ProjectorMaps& maps, const ScanResult& result) {
  const int rows = maps.status.rows, cols = maps.status.cols;
  const std::size_t n = static_cast<std::size_t>(rows) * cols;
  auto floats = [&](const cv::Mat& m) {
    std::vector<float> v(n, std::numeric_limits<float>::quiet_NaN());
    if (!m.empty()) {
      cv::Mat continuous = m.isContinuous() ? m : m.clone();
      std::memcpy(v.data(), continuous.ptr<float>(), n * sizeof(float));
    }
    return v;
  };
  std::vector<float> up = floats(maps.up), vp = floats(maps.vp), mod = floats(maps.modulation);
  cv::Mat status = maps.status.isContinuous() ? maps.status : maps.status.clone();
  std::string frame_id = config.frame_id;
  std::string pattern = result.pattern;
  Maps msg{};
  msg.header.stamp = toTime(maps.stamp_ns);
  msg.header.frame_id = frame_id.data();
  msg.pattern = pattern.data();
  msg.scan_index = result.scan_index;
  msg.height = static_cast<std::uint32_t>(rows);
  msg.width = static_cast<std::uint32_t>(cols);
  borrow(msg.up, up.data(), n);
  borrow(msg.vp, vp.data(), n);
  borrow(msg.modulation, mod.data(), n);
  borrow(msg.status, status.ptr<std::uint8_t>(), n);
  if (!maps_writer.write(msg)) ++writes_timed_out;
}

// Depth (32FC1, metres, NaN invalid: the ROS depth image convention) and
// shading (mono8: the offset A scaled from the camera's bit depth) images of
// one scan, and the triangulating camera's calibration.
void DdsBridge::Impl::publishImages(const ScanResult& result) {
  const pipeline::PointCloud& cloud = *result.cloud;
  const std::size_t n = cloud.points.size();
  std::vector<float> depth(n);
  std::vector<std::uint8_t> shading(n);
  const int bit_depth = result.bit_depth;
  const float to_8bit = 255.0f / float((1 << bit_depth) - 1);
  const float to_metres = static_cast<float>(result.cloud_unit_m);
  for (std::size_t i = 0; i < n; ++i) {
    depth[i] = cloud.points[i].z * to_metres;
    const float a = cloud.points[i].intensity * to_8bit;
    shading[i] = std::isfinite(a) ? static_cast<std::uint8_t>(std::clamp(a + 0.5f, 0.0f, 255.0f)) : 0;
  }
  std::string frame_id = frame_ids.of(result.camera_id), enc_depth = "32FC1", enc_mono = "mono8";
  auto image = [&](std::string& encoding, void* data, std::uint32_t bytes_per_pixel) {
    Image msg{};
    msg.header.stamp = toTime(cloud.stamp_ns);
    msg.header.frame_id = frame_id.data();
    msg.height = static_cast<std::uint32_t>(cloud.height);
    msg.width = static_cast<std::uint32_t>(cloud.width);
    msg.encoding = encoding.data();
    msg.is_bigendian = 0;
    msg.step = msg.width * bytes_per_pixel;
    borrow(msg.data, static_cast<std::uint8_t*>(data), n * bytes_per_pixel);
    return msg;
  };
  if (!depth_writer.write(image(enc_depth, depth.data(), 4))) ++writes_timed_out;
  if (!shading_writer.write(image(enc_mono, shading.data(), 1))) ++writes_timed_out;
  // camera_info describes the first camera (whose frame is dds.frame_id);
  // images of other cameras carry their own frame_id and no camera_info yet.
  if (result.camera_id != frame_ids.first_camera_id) return;

  std::string model = "plumb_bob";
  std::vector<double> d(camera.distortion.begin(), camera.distortion.end());
  CameraInfo info{};
  info.header.stamp = toTime(cloud.stamp_ns);
  info.header.frame_id = frame_id.data();
  info.height = static_cast<std::uint32_t>(camera.height);
  info.width = static_cast<std::uint32_t>(camera.width);
  info.distortion_model = model.data();
  borrow(info.d, d.data(), d.size());
  const double k[9] = {camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1};
  std::copy(std::begin(k), std::end(k), info.k);
  const double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::copy(std::begin(r), std::end(r), info.r);
  const double p[12] = {camera.fx, 0, camera.cx, 0, 0, camera.fy, camera.cy, 0, 0, 0, 1, 0};
  std::copy(std::begin(p), std::end(p), info.p);
  info.binning_x = info.binning_y = 0;
  info.roi = {0, 0, 0, 0, false};
  info_writer.write(info);
}

// All images of one sequence as acquired, camera-major, each stamped with
// its exposure time (see idl/sl_msgs/msg/ImageSet.idl).
void DdsBridge::Impl::publishImageSet(const pipeline::ImageSet& set) {
  std::size_t total = 0;
  for (const auto& c : set.cameras) total += c.frames.size();
  std::vector<Image> images(total);
  std::vector<std::string> optical_frames, camera_ids;
  std::vector<std::uint8_t> bit_depths;
  std::vector<cv::Mat> continuous;  // copies only of non-continuous frames (none from cameras)
  continuous.reserve(total);
  std::string mono8 = "mono8", mono16 = "mono16", pattern = set.pattern_name;
  for (std::size_t k = 0; k < set.cameras.size(); ++k) {
    optical_frames.push_back(frame_ids.of(set.cameras[k].camera_id));
    camera_ids.push_back(set.cameras[k].camera_id);
    bit_depths.push_back(static_cast<std::uint8_t>(set.cameras[k].bit_depth));
  }
  std::size_t i = 0;
  for (std::size_t k = 0; k < set.cameras.size(); ++k) {
    const pipeline::CameraImages& c = set.cameras[k];
    for (std::size_t f = 0; f < c.frames.size(); ++f, ++i) {
      continuous.push_back(c.frames[f].isContinuous() ? c.frames[f] : c.frames[f].clone());
      const cv::Mat& m = continuous.back();
      Image& msg = images[i];
      msg.header.stamp = toTime(c.stamps_ns[f]);
      msg.header.frame_id = optical_frames[k].data();
      msg.height = static_cast<std::uint32_t>(m.rows);
      msg.width = static_cast<std::uint32_t>(m.cols);
      msg.encoding = m.elemSize() == 1 ? mono8.data() : mono16.data();
      msg.is_bigendian = 0;  // little endian, as in memory
      msg.step = static_cast<std::uint32_t>(m.cols * m.elemSize());
      borrow(msg.data, const_cast<std::uint8_t*>(m.ptr<std::uint8_t>()), m.total() * m.elemSize());
    }
  }
  StringList ids(camera_ids);
  std::string empty;
  ImageSetMsg msg{};
  msg.header.stamp = toTime(set.trigger_stamp_ns);
  msg.header.frame_id = empty.data();
  msg.pattern = pattern.data();
  msg.sequence_id = set.sequence_id;
  msg.camera_count = static_cast<std::uint32_t>(set.cameras.size());
  borrow(msg.camera_ids, ids.pointers.data(), ids.pointers.size());
  borrow(msg.bit_depths, bit_depths.data(), bit_depths.size());
  borrow(msg.images, images.data(), images.size());
  if (!sets_writer.write(msg)) ++writes_timed_out;
}

void DdsBridge::Impl::publishStatus(const EngineStatus& s,
                                    const std::vector<std::string>& patterns) {
  std::string pattern = s.pattern, last_error = s.last_error, recording = s.recording,
              degraded = s.degraded_reason;
  StringList names(patterns);
  Status msg{};
  msg.stamp = toTime(pipeline::systemClockNs());
  msg.state = toState(s.state);
  msg.pattern = pattern.data();
  msg.scans_done = s.scans_done;
  msg.scans_requested = s.scans_requested;
  msg.scan_rate_hz = s.scan_rate_hz;
  const std::uint64_t timed_out = writes_timed_out.load();
  msg.frames_dropped = s.frames_dropped;
  msg.sets_dropped = s.sets_dropped + timed_out;
  msg.sets_incomplete = s.sets_incomplete;
  msg.frames_overflow = s.frames_overflow;
  msg.frames_unmatched = s.frames_unmatched;
  msg.sets_overflow = s.sets_overflow;
  msg.writes_timed_out = timed_out;
  msg.sets_not_recorded = s.sets_not_recorded;
  msg.trigger = s.trigger == TriggerMode::kSoftware ? sl_msgs_msg_TRIGGER_SOFTWARE
                                                    : sl_msgs_msg_TRIGGER_HARDWARE;
  StringList cameras(s.cameras);
  borrow(msg.cameras, cameras.pointers.data(), cameras.pointers.size());
  msg.motion_compensation = s.motion_compensation;
  msg.start_at = toTime(s.start_at_ns);
  msg.frame_rate_hz = s.frame_rate_hz;
  msg.last_error = last_error.data();
  msg.recording = recording.data();
  msg.sets_recorded = s.sets_recorded;
  borrow(msg.patterns, names.pointers.data(), names.pointers.size());
  msg.requests_received = guard.counters.received;
  msg.requests_answered = guard.counters.answered;
  msg.requests_rate_limited = guard.counters.rate_limited;
  msg.requests_invalid = guard.counters.invalid;
  msg.replies_timed_out = replies_timed_out;
  msg.degraded_reason = degraded.data();
  msg.last_error_stamp = toTime(s.last_error_ns);
  msg.errors_reported = s.errors_reported;
  msg.requests_malformed = malformed.count();
  msg.sets_over_quota = s.sets_over_quota;
  status_writer.write(msg);
}

void DdsBridge::Impl::answer(ScanEngine& engine, const Request& request) {
  CommandResult result;
  const std::string pattern = request.pattern ? request.pattern : "";
  // Oversized fields are refused before anything else reads them; the reply
  // and the log carry a short excerpt only.
  const std::string size_problem = guard.checkSizes(request);
  const std::string client_id =
      request.client_id && std::strlen(request.client_id) <= guard.limits().max_string
          ? request.client_id
          : excerpt(request.client_id);
  const bool changes_state = request.command == sl_msgs_msg_COMMAND_START ||
                             request.command == sl_msgs_msg_COMMAND_STOP ||
                             request.command == sl_msgs_msg_COMMAND_SET_PATTERN;
  const CommandResult* earlier =
      changes_state ? guard.repeated(client_id, request.request_id) : nullptr;
  if (!size_problem.empty()) {
    ++guard.counters.invalid;
    result = {CommandResult::Code::kInvalidOption, size_problem};
  } else if (earlier) {
    result = *earlier;  // a client's retry: the first answer again
  } else switch (request.command) {
    case sl_msgs_msg_COMMAND_START: {
      std::string error;
      const StartRequest start = toStartRequest(request, error);
      result = error.empty() ? engine.start(start)
                             : CommandResult{CommandResult::Code::kInvalidOption, error};
      break;
    }
    case sl_msgs_msg_COMMAND_STOP:
      result = engine.stop();
      break;
    case sl_msgs_msg_COMMAND_SET_PATTERN:
      result = engine.selectPattern(pattern);
      break;
    case sl_msgs_msg_COMMAND_LIST_PATTERNS:
    case sl_msgs_msg_COMMAND_GET_CONFIG:
      break;  // every reply lists the patterns; the config text is added below
    default:
      result = {CommandResult::Code::kInvalidCommand,
                "unknown command " + std::to_string(static_cast<int>(request.command))};
  }
  if (changes_state && size_problem.empty() && !earlier)
    guard.remember(client_id, request.request_id, result);
  std::string reply_client_id = client_id;
  std::string reason = result.reason;
  static const char* kCommands[] = {"start", "stop", "set_pattern", "list_patterns",
                                    "get_config"};
  const int command = static_cast<int>(request.command);
  if ((command < 3 || !result.accepted()) && !earlier)  // queries are not worth a log line
    logInfo("request " + std::to_string(request.request_id) + " from client " +
          excerpt(request.client_id, 64) + ": " +
          (command >= 0 && command < 5 ? kCommands[command] : "unknown") +
          (pattern.empty() ? "" : " '" + excerpt(request.pattern, 64) + "'") +
          (request.command == sl_msgs_msg_COMMAND_START && size_problem.empty()
               ? describeStart(request)
               : "") +
          (result.accepted() ? ": accepted" : ": rejected: " + reason));
  StringList names(engine.patterns());
  Reply reply{};
  reply.client_id = reply_client_id.data();
  reply.request_id = request.request_id;
  reply.accepted = result.accepted();
  reply.code = toReplyCode(result.code);
  reply.reason = reason.data();
  std::string detail =
      request.command == sl_msgs_msg_COMMAND_GET_CONFIG ? engine.config().source_text : "";
  reply.detail = detail.data();
  borrow(reply.patterns, names.pointers.data(), names.pointers.size());
  if (reply_writer.write(reply)) ++guard.counters.answered;
  else ++replies_timed_out;
}

DdsBridge::DdsBridge(const DdsConfig& config, const std::string& camera_id,
                     const pipeline::PinholeModel& camera)
    : impl_(std::make_unique<Impl>(config, camera_id, camera)) {}
DdsBridge::~DdsBridge() = default;

void DdsBridge::publish(const ScanResult& result) {
  if (result.cloud) impl_->publishCloud(*result.cloud, result.cloud_unit_m, impl_->frame_ids.of(result.camera_id));
  // After the cloud, which then does not wait for the set's serialization.
  if (impl_->config.publish_image_sets && result.images &&
      result.images->trigger_stamp_ns != impl_->last_set_stamp_ns) {
    impl_->publishImageSet(*result.images);
    impl_->last_set_stamp_ns = result.images->trigger_stamp_ns;
  }
  if (impl_->config.publish_projector_maps && result.maps) impl_->publishMaps(*result.maps, result);
  if (impl_->config.publish_images && result.cloud) impl_->publishImages(result);
}

void DdsBridge::serve(ScanEngine& engine) {
  Impl& d = *impl_;
  using Clock = std::chrono::steady_clock;
  std::uint64_t published_version = ~std::uint64_t{0};
  Clock::time_point next_periodic = Clock::now();
  const std::vector<std::string> patterns = engine.patterns();
  while (!d.stopping) {
    d.waitset.wait(DDS_MSECS(100));
    for (;;) {
      dds::Loan<Request> requests = d.request_reader.take(16);
      if (requests.empty()) break;
      for (std::size_t i = 0; i < requests.size(); ++i) {
        if (!requests.isValid(i)) continue;
        ++d.guard.counters.received;
        const Request& request = requests[i];
        if (!d.guard.admit(request.client_id ? request.client_id : "", std::chrono::duration_cast<std::chrono::nanoseconds>(
                                       std::chrono::steady_clock::now().time_since_epoch()).count())) {
          // Counted, not answered (a flood must not cost a reply each);
          // logged at most every 10 s.
          if (d.guard.counters.rate_limited++ == d.rate_limited_logged) {
            logWarning("requests over the rate limit of " +
                       std::to_string(d.guard.limits().rate_hz) + "/s from client " +
                       excerpt(request.client_id, 64) + " are not answered (counted in status)");
            d.rate_limited_logged = d.guard.counters.rate_limited + 200;
          }
          continue;
        }
        d.answer(engine, request);
      }
    }
    const EngineStatus status = engine.status();
    if (status.version != published_version || Clock::now() >= next_periodic) {
      d.publishStatus(status, patterns);
      published_version = status.version;
      const auto period = std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(d.status_period_s.load()));
      next_periodic = Clock::now() + period;
    }
  }
}

void DdsBridge::setStatusPeriod(double seconds) { impl_->status_period_s = seconds; }

void DdsBridge::stop() {
  impl_->stopping = true;
  impl_->wake.trigger();
}

}  // namespace sl::daemon
