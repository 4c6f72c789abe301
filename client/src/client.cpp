#include "sl/client/client.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <random>
#include <thread>

#include "sl/client/reply_codes.h"
#include "sl/dds/msg_convert.h"
#include "sl/dds/dds.h"
#include "sl/dds/sensor_topics.h"
#include "sl/dds/topic_names.h"

namespace sl::client {

// Moved out of daemon/ (issue 34).
using ::sl::dds::TopicNames;

namespace {

using namespace ::sl::dds::msg;
using Clock = std::chrono::steady_clock;

std::string randomClientId() {
  std::random_device device;
  std::uniform_int_distribution<std::uint64_t> dist;
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(dist(device)));
  return text;
}

// Decodes a PointCloud2 with float32 x, y, z (m) and optional intensity into
// the pipeline type (mm). Throws std::runtime_error on a layout it cannot read.
pipeline::PointCloud toPointCloud(const PointCloud2& msg) {
  int offsets[4] = {-1, -1, -1, -1};
  const char* names[4] = {"x", "y", "z", "intensity"};
  for (std::uint32_t i = 0; i < msg.fields._length; ++i) {
    const auto& f = msg.fields._buffer[i];
    for (int k = 0; k < 4; ++k)
      if (std::strcmp(f.name, names[k]) == 0 && f.datatype == kFloat32)
        offsets[k] = static_cast<int>(f.offset);
  }
  if (offsets[0] < 0 || offsets[1] < 0 || offsets[2] < 0)
    throw std::runtime_error("point cloud has no float32 x, y, z fields");
  if (msg.is_bigendian) throw std::runtime_error("big-endian point clouds are not supported");
  const std::size_t n = static_cast<std::size_t>(msg.width) * msg.height;
  if (msg.data._length < n * msg.point_step || msg.row_step != msg.width * msg.point_step)
    throw std::runtime_error("point cloud data is shorter than width * height * point_step");
  pipeline::PointCloud cloud;
  cloud.frame_id = msg.header.frame_id ? msg.header.frame_id : "";
  cloud.stamp_ns = fromTime(msg.header.stamp);
  cloud.width = static_cast<int>(msg.width);
  cloud.height = static_cast<int>(msg.height);
  cloud.points.resize(n);
  auto readFloat = [&](std::size_t point, int offset) {
    float v;
    std::memcpy(&v, msg.data._buffer + point * msg.point_step + offset, sizeof v);
    return v;
  };
  for (std::size_t i = 0; i < n; ++i) {
    auto& p = cloud.points[i];
    p.x = readFloat(i, offsets[0]) * 1e3f;  // m -> mm
    p.y = readFloat(i, offsets[1]) * 1e3f;
    p.z = readFloat(i, offsets[2]) * 1e3f;
    p.intensity = offsets[3] >= 0 ? readFloat(i, offsets[3]) : 0.0f;
  }
  return cloud;
}

}  // namespace

struct SensorClient::Impl {
  explicit Impl(const ClientOptions& options)
      : options(options),
        topics(options.domain_id, options.ns),
        client_id(randomClientId()),
        request_writer(participant, request_topic, dds::Qos().reliable().keepLast(16).xcdr1()),
        // Transient-local: gets a reply the daemon wrote before its writer
        // had matched this reader (the history's other replies are ignored).
        reply_reader(participant, reply_topic, dds::Qos().reliable().transientLocal().keepLast(64)),
        status_reader(participant, status_topic,
                      dds::Qos().reliable().transientLocal().keepLast(1)) {
    if (options.subscribe_points) {
      points_reader.emplace(participant, points_topic, dds::Qos().reliable().keepLast(8));
    }
  }

  const ClientOptions options;
  dds::SensorTopics topics;
  const TopicNames& names = topics.names;
  const std::string client_id;
  std::uint64_t next_request_id = 1;
  dds::Participant& participant = topics.participant;
  dds::Topic<Request>& request_topic = topics.request;
  dds::Topic<Reply>& reply_topic = topics.reply;
  dds::Topic<Status>& status_topic = topics.status;
  dds::Writer<Request> request_writer;
  dds::Reader<Reply> reply_reader;
  dds::Reader<Status> status_reader;
  dds::Topic<PointCloud2>& points_topic = topics.points;
  std::optional<dds::Reader<PointCloud2>> points_reader;

  // Writes `req` with this client's id and the next request id, and waits
  // for the reply carrying both.
  std::optional<CommandReplyInfo> send(Request& req, std::chrono::milliseconds timeout);
};

SensorClient::SensorClient(const ClientOptions& options)
    : impl_(std::make_unique<Impl>(options)) {}
SensorClient::~SensorClient() = default;

const std::string& SensorClient::clientId() const { return impl_->client_id; }

bool SensorClient::waitForDaemon(std::chrono::milliseconds timeout) {
  Impl& d = *impl_;
  const auto deadline = Clock::now() + timeout;
  auto remaining = [&] {
    return std::max<dds_duration_t>(
        0, std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - Clock::now()).count());
  };
  if (!d.request_writer.waitForReaders(1, remaining())) return false;
  if (!d.reply_reader.waitForWriters(1, remaining())) return false;
  if (d.points_reader && !d.points_reader->waitForWriters(1, remaining())) return false;
  return true;
}

std::optional<CommandReplyInfo> SensorClient::Impl::send(Request& req,
                                                         std::chrono::milliseconds timeout) {
  req.client_id = const_cast<char*>(client_id.c_str());
  req.request_id = next_request_id++;
  const auto deadline = Clock::now() + timeout;
  // Requests other than START are idempotent: sent again with the same id
  // (after 0.5, 1, 2, 2, ... s) while no reply came, e.g. when a flood of
  // other clients' requests delayed or pushed out ours. The daemon answers a
  // repeated STOP / SET_PATTERN with its first reply (RequestGuard), so a
  // retry never turns "stopped" into "not running".
  const bool idempotent = req.command != sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START;
  auto interval = std::chrono::milliseconds(500);
  bool written = request_writer.write(req);
  if (!written && !idempotent) return std::nullopt;
  auto next_send = Clock::now() + interval;
  while (Clock::now() < deadline) {
    if (idempotent && Clock::now() >= next_send) {
      written = request_writer.write(req) || written;
      interval = std::min(interval * 2, std::chrono::milliseconds(2000));
      next_send = Clock::now() + interval;
    }
    dds::Loan<Reply> replies = reply_reader.take(16);
    for (std::size_t i = 0; i < replies.size(); ++i) {
      if (!replies.isValid(i)) continue;
      const Reply& r = replies[i];
      if (r.request_id != req.request_id || std::strcmp(r.client_id, client_id.c_str()) != 0)
        continue;  // another client's reply, or a stale one
      CommandReplyInfo info;
      info.accepted = r.accepted;
      info.code = fromReplyCode(r.code);
      info.reason = r.reason ? r.reason : "";
      info.patterns = toStrings(r.patterns);
      info.detail = r.detail ? r.detail : "";
      return info;
    }
    if (replies.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return std::nullopt;
}

std::optional<CommandReplyInfo> SensorClient::request(Command command, const std::string& pattern,
                                                      int count,
                                                      std::chrono::milliseconds timeout,
                                                      const std::string& recording) {
  std::string pattern_copy = pattern, recording_copy = recording;
  Request req{};
  switch (command) {
    case Command::kStart: req.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START; break;
    case Command::kStop: req.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_STOP; break;
    case Command::kSetPattern: req.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_SET_PATTERN; break;
    case Command::kListPatterns: req.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_LIST_PATTERNS; break;
    case Command::kGetConfig: req.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_GET_CONFIG; break;
  }
  req.pattern = pattern_copy.data();
  req.count = count;
  req.recording = recording_copy.data();
  return impl_->send(req, timeout);
}

std::optional<CommandReplyInfo> SensorClient::start(const StartRequest& request,
                                                    std::chrono::milliseconds timeout) {
  std::string pattern = request.pattern, recording = request.recording;
  std::vector<std::string> cameras = request.cameras;
  std::vector<char*> camera_pointers;
  for (auto& id : cameras) camera_pointers.push_back(id.data());
  Request req{};
  req.command = sl_msgs_msg_dds__CommandRequest_Constants_COMMAND_START;
  req.pattern = pattern.data();
  req.count = request.count;
  req.recording = recording.data();
  req.trigger = !request.trigger                              ? sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_DEFAULT
                : *request.trigger == TriggerMode::kSoftware ? sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_SOFTWARE
                                                             : sl_msgs_msg_dds__CommandRequest_Constants_TRIGGER_HARDWARE;
  req.delay_s = request.delay_s;
  req.start_at = toTime(request.start_at_ns);
  req.cameras._maximum = req.cameras._length = static_cast<std::uint32_t>(camera_pointers.size());
  req.cameras._buffer = camera_pointers.data();
  req.cameras._release = false;
  req.motion_compensation = !request.motion_compensation ? sl_msgs_msg_dds__CommandRequest_Constants_MOTION_DEFAULT
                            : *request.motion_compensation ? sl_msgs_msg_dds__CommandRequest_Constants_MOTION_ON
                                                           : sl_msgs_msg_dds__CommandRequest_Constants_MOTION_OFF;
  return impl_->send(req, timeout);
}

std::optional<pipeline::PointCloud> SensorClient::receiveCloud(
    pipeline::TimestampNs not_before_ns, std::chrono::milliseconds timeout) {
  Impl& d = *impl_;
  if (!d.points_reader) throw std::logic_error("SensorClient: points not subscribed");
  const auto deadline = Clock::now() + timeout;
  while (Clock::now() < deadline) {
    dds::Loan<PointCloud2> clouds = d.points_reader->take(1);
    if (clouds.empty()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      continue;
    }
    if (!clouds.isValid(0) || fromTime(clouds[0].header.stamp) < not_before_ns) continue;
    return toPointCloud(clouds[0]);
  }
  return std::nullopt;
}

std::optional<StatusInfo> SensorClient::status(std::chrono::milliseconds timeout) {
  Impl& d = *impl_;
  const auto deadline = Clock::now() + timeout;
  std::optional<StatusInfo> latest;
  while (!latest && Clock::now() < deadline) {
    dds::Loan<Status> samples = d.status_reader.take(8);
    for (std::size_t i = 0; i < samples.size(); ++i) {
      if (!samples.isValid(i)) continue;
      const Status& s = samples[i];
      StatusInfo info;
      info.state = s.state == sl_msgs_msg_dds__Status_Constants_STATE_SCANNING ? ScanState::kScanning
                   : s.state == sl_msgs_msg_dds__Status_Constants_STATE_IDLE   ? ScanState::kIdle
                   : s.state == sl_msgs_msg_dds__Status_Constants_STATE_WAITING ? ScanState::kWaiting
                   : s.state == sl_msgs_msg_dds__Status_Constants_STATE_DEGRADED ? ScanState::kDegraded
                                                         : ScanState::kError;
      info.pattern = s.pattern ? s.pattern : "";
#define SL_COPY_FIELD(type, name, label) info.name = s.name;
      SL_STATUS_ENGINE_FIELDS(SL_COPY_FIELD)
#undef SL_COPY_FIELD
      info.sets_dropped = s.sets_dropped;
      info.writes_timed_out = s.writes_timed_out;
      info.images_not_compressed = s.images_not_compressed;
      info.trigger = s.trigger == sl_msgs_msg_dds__Status_Constants_TRIGGER_SOFTWARE ? TriggerMode::kSoftware
                                                             : TriggerMode::kHardware;
      info.cameras = toStrings(s.cameras);
      info.motion_compensation = s.motion_compensation;
      info.start_at_ns = fromTime(s.start_at);
      info.last_error = s.last_error ? s.last_error : "";
      info.recording = s.recording ? s.recording : "";
      info.patterns = toStrings(s.patterns);
      info.stamp_ns = fromTime(s.stamp);
      info.requests_received = s.requests_received;
      info.requests_answered = s.requests_answered;
      info.requests_rate_limited = s.requests_rate_limited;
      info.requests_invalid = s.requests_invalid;
      info.replies_timed_out = s.replies_timed_out;
      info.degraded_reason = s.degraded_reason ? s.degraded_reason : "";
      info.last_error_ns = fromTime(s.last_error_stamp);
      info.requests_malformed = s.requests_malformed;
      info.requests_rejected = s.requests_rejected;
      info.clouds_lost_to_readers = s.clouds_lost_to_readers;
      info.adaptive_mode = s.adaptive_mode ? s.adaptive_mode : "";
      info.adaptive_reason = s.adaptive_reason ? s.adaptive_reason : "";
      for (std::uint32_t k = 0; k < s.points_readers._length; ++k) {
        const auto& r = s.points_readers._buffer[k];
        info.points_readers.push_back(
            {r.guid ? r.guid : "", r.reliable, r.acknowledging, r.clouds_lost});
      }
      latest = info;
    }
    if (!latest) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return latest;
}

}  // namespace sl::client
