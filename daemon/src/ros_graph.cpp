#include "ros_graph.h"

#include <algorithm>
#include <cstdio>
#include <cstring>

#include "msg_convert.h"  // toTime

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::ScanState;

namespace {

char* chars(const std::string& s) { return const_cast<char*>(s.c_str()); }

template <typename T>
T* data(std::vector<T>& v) {
  return v.empty() ? nullptr : v.data();
}

template <typename Seq, typename T>
void setSequence(Seq& seq, std::vector<T>& v) {
  seq._maximum = seq._length = static_cast<std::uint32_t>(v.size());
  seq._buffer = data(v);
  seq._release = false;
}

std::string number(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", v);
  return text;
}
std::string number(std::uint64_t v) { return std::to_string(v); }

// The parts of a degraded cause ("a; b; c").
std::vector<std::string> causeParts(const std::string& cause) {
  std::vector<std::string> parts;
  std::size_t begin = 0;
  while (begin < cause.size()) {
    std::size_t end = cause.find("; ", begin);
    if (end == std::string::npos) end = cause.size();
    parts.push_back(cause.substr(begin, end - begin));
    begin = end + 2;
  }
  return parts;
}

bool startsWith(const std::string& s, const std::string& prefix) { return s.rfind(prefix, 0) == 0; }

}  // namespace

TfStaticPublisher::TfStaticPublisher(const dds::Participant& participant,
                                     const std::vector<FrameTransform>& transforms, std::int64_t stamp_ns)
    : topic_(participant, "rt/tf_static", tf2_msgs_msg_dds__TFMessage__desc),
      writer_(participant, topic_, dds::Qos().reliable().transientLocal().keepLast(1).xcdr1()) {
  std::vector<geometry_msgs_msg_dds__TransformStamped_> samples(transforms.size());
  for (std::size_t i = 0; i < transforms.size(); ++i) {
    const FrameTransform& t = transforms[i];
    auto& s = samples[i];
    s.header.stamp = msg::toTime(stamp_ns);
    s.header.frame_id = chars(t.parent);
    s.child_frame_id = chars(t.child);
    const Eigen::Vector3d p = t.pose.translation();
    const Eigen::Quaterniond q(t.pose.rotation());
    s.transform.translation = {p.x(), p.y(), p.z()};
    s.transform.rotation = {q.x(), q.y(), q.z(), q.w()};
  }
  tf2_msgs_msg_dds__TFMessage_ message{};
  setSequence(message.transforms, samples);
  writer_.write(message);
}

std::vector<Diagnostic> diagnosticsOf(const EngineStatus& s, const DiagnosticInputs& in) {
  constexpr std::uint8_t kOk = 0, kWarn = 1, kError = 2;
  const std::vector<std::string> cause =
      s.state == ScanState::kDegraded ? causeParts(s.degraded_reason) : std::vector<std::string>{};
  const bool scanning = s.state == ScanState::kScanning || s.state == ScanState::kDegraded;
  std::vector<Diagnostic> out;
  auto device = [&](const std::string& name, const std::string& hardware_id, const std::string& prefix) {
    Diagnostic d;
    d.name = in.node_name + ": " + name;
    d.hardware_id = hardware_id;
    for (const auto& part : cause)
      if (startsWith(part, prefix)) {
        d.level = kWarn;
        d.message += (d.message.empty() ? "" : "; ") + part;
      }
    // An error the device reported and that has not recovered yet.
    if (startsWith(s.last_error, prefix)) {
      d.level = kError;
      d.message = s.last_error + (d.message.empty() ? "" : "; " + d.message);
    }
    if (d.level == kOk) d.message = scanning ? "delivering" : "idle";
    d.values.emplace_back("state", toString(s.state));
    return d;
  };
  for (const auto& id : in.camera_ids) {
    Diagnostic d = device("camera " + id, id, "camera '" + id + "'");
    d.values.emplace_back("frame_rate_hz (all cameras)", number(s.frame_rate_hz));
    out.push_back(std::move(d));
  }
  out.push_back(device("trigger source", toString(s.trigger), "trigger source"));

  Diagnostic p;
  p.name = in.node_name + ": pipeline";
  p.hardware_id = "pipeline";
  switch (s.state) {
    case ScanState::kError:
      p.level = kError;
      p.message = s.last_error.empty() ? "error" : s.last_error;
      break;
    case ScanState::kDegraded:
      p.level = kWarn;
      p.message = "degraded: " + s.degraded_reason;
      break;
    default:
      p.level = kOk;
      p.message = toString(s.state);
      if (s.state == ScanState::kScanning) p.message += " " + s.pattern + " at " + number(s.scan_rate_hz) + " Hz";
  }
  std::uint64_t lost = 0;
  for (const auto& r : in.points_readers) lost += r.lost;
  if (p.level == kOk && lost > 0) {
    p.level = kWarn;
    p.message += "; points readers lost " + std::to_string(lost) + " clouds";
  }
  auto add = [&p](const std::string& key, const std::string& value) { p.values.emplace_back(key, value); };
  add("state", toString(s.state));
  add("pattern", s.pattern);
  // Every engine counter (sl/client/status_fields.h), keyed by its name.
#define SL_ADD_FIELD(type, name, label) add(#name, number(s.name));
  SL_STATUS_ENGINE_FIELDS(SL_ADD_FIELD)
#undef SL_ADD_FIELD
  add("sets_dropped", std::to_string(s.sets_dropped));
  add("writes_timed_out", std::to_string(in.writes_timed_out));
  add("images_not_compressed", std::to_string(in.images_not_compressed));
  add("clouds_lost_to_readers", std::to_string(in.clouds_lost_to_readers));
  for (const auto& r : in.points_readers)
    add("clouds lost by points reader " + r.guid,
        r.reliable ? std::to_string(r.lost) : std::string("best effort (not seen)"));
  add("requests_received", std::to_string(in.requests.received));
  add("requests_answered", std::to_string(in.requests.answered));
  add("requests_rate_limited", std::to_string(in.requests.rate_limited));
  add("degraded_reason", s.degraded_reason);
  add("last_error", s.last_error);
  add("recording", s.recording);
  out.push_back(std::move(p));
  return out;
}

DiagnosticsPublisher::DiagnosticsPublisher(const dds::Participant& participant)
    : topic_(participant, "rt/diagnostics", diagnostic_msgs_msg_dds__DiagnosticArray__desc),
      writer_(participant, topic_, dds::Qos().reliable(DDS_MSECS(100)).keepLast(1).xcdr1()) {}

bool DiagnosticsPublisher::publish(const std::vector<Diagnostic>& statuses, std::int64_t stamp_ns) {
  std::vector<std::vector<diagnostic_msgs_msg_dds__KeyValue_>> values(statuses.size());
  std::vector<diagnostic_msgs_msg_dds__DiagnosticStatus_> samples(statuses.size());
  for (std::size_t i = 0; i < statuses.size(); ++i) {
    const Diagnostic& d = statuses[i];
    for (const auto& [k, v] : d.values) values[i].push_back({chars(k), chars(v)});
    auto& s = samples[i];
    s.level = d.level;
    s.name = chars(d.name);
    s.message = chars(d.message);
    s.hardware_id = chars(d.hardware_id);
    setSequence(s.values, values[i]);
  }
  const std::string frame;
  diagnostic_msgs_msg_dds__DiagnosticArray_ message{};
  message.header.stamp = msg::toTime(stamp_ns);
  message.header.frame_id = chars(frame);
  setSequence(message.status, samples);
  return writer_.write(message);
}

DiscoveryInfoPublisher::DiscoveryInfoPublisher(const dds::Participant& participant,
                                               std::string node_namespace, std::string node_name)
    : participant_(participant.handle()),
      namespace_(std::move(node_namespace)),
      name_(std::move(node_name)),
      topic_(participant, "ros_discovery_info", rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc),
      writer_(participant, topic_, dds::Qos().reliable().transientLocal().keepLast(1).xcdr1()) {}

void DiscoveryInfoPublisher::publish() {
  auto gidOf = [](dds_entity_t e) {
    rmw_dds_common_msg_dds__Gid_ gid{};
    dds_guid_t guid{};
    if (dds_get_guid(e, &guid) == DDS_RETCODE_OK) std::memcpy(gid.data, guid.v, sizeof guid.v);
    return gid;
  };
  auto children = [](dds_entity_t e) {
    std::vector<dds_entity_t> out(64);
    for (;;) {
      const dds_return_t n = dds_get_children(e, out.data(), out.size());
      if (n < 0) return std::vector<dds_entity_t>{};
      if (static_cast<std::size_t>(n) <= out.size()) {
        out.resize(static_cast<std::size_t>(n));
        return out;
      }
      out.resize(static_cast<std::size_t>(n));
    }
  };
  // Readers and writers sit under the participant's (implicit) subscribers
  // and publishers: a writer has a publisher, a reader a subscriber (asking
  // for matched statuses instead would reset them under other waiters).
  // Built-in readers (DCPS* topics: entity kinds 0xc_) are not the node's,
  // as rmw skips them.
  auto builtIn = [](dds_entity_t e) {
    dds_guid_t guid{};
    return dds_get_guid(e, &guid) == DDS_RETCODE_OK && (guid.v[15] & 0xc0) == 0xc0;
  };
  std::vector<rmw_dds_common_msg_dds__Gid_> readers, writers;
  for (dds_entity_t parent : children(participant_))
    for (dds_entity_t e : children(parent)) {
      if (e == writer_.handle() || builtIn(e)) continue;
      if (dds_get_publisher(e) > 0)
        writers.push_back(gidOf(e));
      else if (dds_get_subscriber(e) > 0)
        readers.push_back(gidOf(e));
    }
  rmw_dds_common_msg_dds__NodeEntitiesInfo_ node{};
  // Bounded strings (string<=256) are char arrays in idlc's C types.
  std::snprintf(node.node_namespace, sizeof node.node_namespace, "%s", namespace_.c_str());
  std::snprintf(node.node_name, sizeof node.node_name, "%s", name_.c_str());
  setSequence(node.reader_gid_seq, readers);
  setSequence(node.writer_gid_seq, writers);
  std::vector<rmw_dds_common_msg_dds__NodeEntitiesInfo_> nodes{node};
  rmw_dds_common_msg_dds__ParticipantEntitiesInfo_ message{};
  message.gid = gidOf(participant_);
  setSequence(message.node_entities_info_seq, nodes);
  writer_.write(message);
}

}  // namespace sl::daemon
