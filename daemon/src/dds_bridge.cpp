#include "sl/daemon/dds_bridge.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "sl/daemon/bounded_queue.h"
#include "sl/dds/cloud_writer.h"
#include "sl/dds/malformed_samples.h"
#include "reader_acks.h"
#include "request_dispatch.h"
#include "request_origin.h"
#include "service_bridge.h"
#include "ros_graph.h"
#include "ros_messages.h"
#include "velocity_input.h"
#include "sl/dds/cloud_layout.h"
#include "sl/dds/dds.h"
#include "sl/dds/sensor_topics.h"
#include "sl/dds/environment.h"
#include "sl/daemon/log.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::dds::CloudWriter;
using ::sl::client::CommandResult;
using ::sl::dds::MalformedSampleCounter;
using ::sl::dds::PackedCloud;
using ::sl::client::StartRequest;
using ::sl::dds::TopicNames;
using ::sl::dds::packCloud;
using ::sl::dds::packsInPlace;
using ::sl::dds::readDdsRequirements;

namespace {

using namespace msg;

// A writer's QoS from the configuration (README "Topics").
dds::Qos writerQos(const TopicQos& q) {
  dds::Qos qos;
  if (q.reliable)
    qos.reliable(static_cast<dds_duration_t>(std::llround(q.max_blocking_s * 1e9)));
  else
    qos.bestEffort();
  return qos.keepLast(q.depth).xcdr1();
}

// zlib level of the compressed images: the fastest (image_transport's
// default, 9, takes several times longer for little gain on these images,
// and the encoder thread must keep up with the scan rate).
constexpr int kPngLevel = 1;

// Why the points writer must serialize clouds (empty: it may borrow them).
// An iceoryx reader gets only what dds_write puts in shared memory, so with
// shared memory configured (or a configuration that cannot be read) clouds
// are serialized.
std::string serializeReason(const DdsConfig& config) {
  if (!config.points_zero_copy) return "dds.points_zero_copy is false";
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri == nullptr || *uri == '\0') return {};
  try {
    if (readDdsRequirements(uri).shared_memory) return "shared memory (iceoryx) is configured";
  } catch (const std::exception& e) {
    return std::string("the DDS configuration could not be read: ") + e.what();
  }
  return {};
}

// Where the ROS 2 services' Fast DDS participant runs (service_bridge.h):
// the domain, and the IPv4 addresses, peers and multicast of the Cyclone
// configuration; nullopt when it must not run (fastDdsServicesDisabled),
// which is logged.
std::optional<dds::FastDdsServiceOptions> fastDdsOptions(const DdsConfig& config) {
  dds::DdsRequirements cyclone;
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri != nullptr && *uri != '\0') {
    try {
      cyclone = readDdsRequirements(uri);
    } catch (const std::exception&) {
      // Cyclone itself refuses an unreadable configuration.
    }
  }
  if (const std::optional<std::string> why = dds::fastDdsServicesDisabled(cyclone.security)) {
    logInfo("ROS 2 services: rmw_fastrtps clients not served (" + *why + ")");
    return std::nullopt;
  }
  dds::FastDdsServiceOptions options;
  options.domain_id = static_cast<std::uint32_t>(config.domain_id);
  options.ipv4_addresses = cyclone.interface_addresses;
  options.ipv4_peers = cyclone.peer_addresses;
  options.allow_multicast = cyclone.allow_multicast;
  return options;
}

// Requests act on the scan engine.
class EngineCommands : public CommandTarget {
 public:
  explicit EngineCommands(ScanEngine& engine) : engine_(engine) {}
  CommandResult start(const StartRequest& request) override { return engine_.start(request); }
  CommandResult stop() override { return engine_.stop(); }
  CommandResult selectPattern(const std::string& pattern) override { return engine_.selectPattern(pattern); }
  std::vector<std::string> patterns() const override { return engine_.patterns(); }
  std::string configText() const override { return engine_.config().source_text; }

 private:
  ScanEngine& engine_;
};

}  // namespace

bool FrameIds::isFirst(const std::string& camera_id) const { return camera_id == first_camera_id; }

std::string FrameIds::of(const std::string& camera_id) const {
  return isFirst(camera_id) ? first_frame_id : camera_id + "_optical_frame";
}

namespace {

// Every camera, the first first, with its frame and calibration.
std::vector<CameraFrame> cameraFrames(
    const FrameIds& ids, const pipeline::CameraProjectorCalibration& first,
    const std::map<std::string, pipeline::CameraProjectorCalibration>& others) {
  std::vector<CameraFrame> out{{ids.first_camera_id, ids.first_frame_id, first}};
  for (const auto& [id, calibration] : others)
    if (id != ids.first_camera_id) out.push_back({id, ids.of(id), calibration});
  return out;
}

}  // namespace

struct DdsBridge::Impl {
  Impl(const DdsConfig& config, const std::string& camera_id,
       const pipeline::CameraProjectorCalibration& calibration,
       const std::map<std::string, pipeline::CameraProjectorCalibration>& other_cameras)
      : config(config),
        frame_ids{camera_id, config.frame_id},
        camera(calibration.camera),
        cameras(cameraFrames(frame_ids, calibration, other_cameras)),
        topics(config.domain_id, config.ns),
        depth_rect_topic(participant, names.depth_image_rect, sensor_msgs_msg_dds__Image__desc),
        depth_info_topic(participant, names.depth_camera_info, sensor_msgs_msg_dds__CameraInfo__desc),
        shading_info_topic(participant, names.shading_camera_info, sensor_msgs_msg_dds__CameraInfo__desc),
        shading_png_topic(participant, names.shading_compressed, sensor_msgs_msg_dds__CompressedImage__desc),
        depth_png_topic(participant, names.depth_rect_compressed_depth, sensor_msgs_msg_dds__CompressedImage__desc),
        // Clouds, maps, images: as configured (dds.qos; by default reliable
        // with a short keep-last history: a write waits at most
        // max_blocking_s for acknowledgements, then it is counted as timed out).
        points_writer(participant, points_topic, writerQos(config.points_qos), serializeReason(config)),
        maps_writer(participant, maps_topic, writerQos(config.maps_qos)),
        // Status: the latest value for late joiners.
        status_writer(participant, status_topic,
                      dds::Qos().reliable().transientLocal().keepLast(1).xcdr1()),
        // Requests: keep-all with a bound, so that a flood is held back by
        // the reliable protocol (the writer blocks) instead of overwriting
        // unread requests without a trace.
        request_reader(participant, request_topic,
                       dds::Qos().reliable().keepAll().resourceLimits(256, -1, -1)),
        // Replies: transient-local, so that a reply written before this
        // writer has matched the client's reader (discovery of the client's
        // reader can lag its request, most under load) is delivered when it
        // matches instead of being lost.
        reply_writer(participant, reply_topic,
                     dds::Qos().reliable().transientLocal().keepLast(64).xcdr1()),
        depth_writer(participant, depth_topic, writerQos(config.images_qos)),
        shading_writer(participant, shading_topic, writerQos(config.images_qos)),
        info_writer(participant, info_topic, writerQos(config.images_qos)),
        depth_rect_writer(participant, depth_rect_topic, writerQos(config.images_qos)),
        depth_info_writer(participant, depth_info_topic, writerQos(config.images_qos)),
        shading_info_writer(participant, shading_info_topic, writerQos(config.images_qos)),
        shading_png_writer(participant, shading_png_topic, writerQos(config.images_qos)),
        depth_png_writer(participant, depth_png_topic, writerQos(config.images_qos)),
        sets_writer(participant, sets_topic, writerQos(config.image_sets_qos)),
        request_condition(request_reader),
        wake(participant),
        waitset(participant) {
    if (config.publish_images && camera.width >= 2 && camera.height >= 2 && camera.fx > 0 && camera.fy > 0)
      rectifier.emplace(camera);
    waitset.attach(request_condition, 1);
    waitset.attach(wake, 2);
    services.attach(waitset, 3);
    if (config.points_qos.reliable) points_acks.emplace(points_writer.handle(), config.points_qos.depth);
    if (points_writer.borrowing())
      logInfo("points: clouds are sent from their own memory (no serialization copy)");
    else
      logInfo("points: clouds are serialized by dds_write: " + points_writer.whyNotBorrowing());

    // ROS 2's graph (ros_graph.h).
    if (config.tf.publish)
      tf_static.emplace(participant, sensorTransforms(config.tf, cameras), pipeline::systemClockNs());
    discovery.publish();  // after every reader and writer exists
    encoder = std::thread([this] { encodeLoop(); });
  }

  // A buffer for a packed cloud that no earlier sample still borrows. The
  // fence orders Cyclone's last reads of it (before its thread dropped the
  // sample's reference) before our writes.
  std::shared_ptr<std::vector<float>> packBuffer() {
    for (const auto& b : pack_buffers) {
      if (b.use_count() != 1) continue;
      std::atomic_thread_fence(std::memory_order_acquire);
      return b;
    }
    auto b = std::make_shared<std::vector<float>>();
    if (pack_buffers.size() < kPackBuffers) pack_buffers.push_back(b);
    return b;
  }

  const DdsConfig config;
  const FrameIds frame_ids;
  const pipeline::PinholeModel camera;  // of the first camera, for camera_info
  const std::vector<CameraFrame> cameras;  // every camera, the first first (tf, diagnostics)
  dds::SensorTopics topics;
  const TopicNames& names = topics.names;
  MalformedSampleCounter malformed{names.request, sl_msgs_msg_dds__CommandRequest__desc.m_typename};  // before the reader
  dds::Participant& participant = topics.participant;
  dds::Topic<PointCloud2>& points_topic = topics.points;
  dds::Topic<Maps>& maps_topic = topics.projector_maps;
  dds::Topic<Status>& status_topic = topics.status;
  dds::Topic<Request>& request_topic = topics.request;
  dds::Topic<Reply>& reply_topic = topics.reply;
  dds::Topic<Image>& depth_topic = topics.depth_image;
  dds::Topic<Image>& shading_topic = topics.shading_image;
  dds::Topic<CameraInfo>& info_topic = topics.camera_info;
  dds::Topic<Image> depth_rect_topic;
  dds::Topic<CameraInfo> depth_info_topic;
  dds::Topic<CameraInfo> shading_info_topic;
  dds::Topic<CompressedImage> shading_png_topic;
  dds::Topic<CompressedImage> depth_png_topic;
  dds::Topic<ImageSetMsg>& sets_topic = topics.image_sets;
  CloudWriter points_writer;
  dds::Writer<Maps> maps_writer;
  dds::Writer<Status> status_writer;
  dds::Reader<Request> request_reader;
  dds::Writer<Reply> reply_writer;
  dds::Writer<Image> depth_writer;
  dds::Writer<Image> shading_writer;
  dds::Writer<CameraInfo> info_writer;
  dds::Writer<Image> depth_rect_writer;
  dds::Writer<CameraInfo> depth_info_writer;
  dds::Writer<CameraInfo> shading_info_writer;
  dds::Writer<CompressedImage> shading_png_writer;
  dds::Writer<CompressedImage> depth_png_writer;
  // The first camera's depth onto its rectified grid (when publish_images).
  std::optional<DepthRectifier> rectifier;
  dds::Writer<ImageSetMsg> sets_writer;
  dds::ReadCondition request_condition;
  dds::GuardCondition wake;
  dds::WaitSet waitset;
  // Which readers of the points topic acknowledge, and the clouds each lost
  // (reliable points only; destroyed before the writer).
  std::optional<ReaderAckMonitor> points_acks;
  std::atomic<bool> stopping{false};
  std::atomic<double> status_period_s{config.status_period_s};  // reloadable
  std::atomic<std::uint64_t> writes_timed_out{0};
  // Requests: sizes, rate limits, retries, counters (request loop only).
  RequestDispatcher dispatcher{config.requests};
  RequestOrigins origins;  // the participant of each request's writer (request loop only)
  // ROS 2 services (<ns>/start, stop, ...) through the same dispatcher.
  ServiceBridge services{participant, config.ns, fastDdsOptions(config)};
  // ROS 2's graph: /tf_static, /diagnostics (1 Hz), ros_discovery_info.
  std::optional<TfStaticPublisher> tf_static;
  DiagnosticsPublisher diagnostics{participant};
  DiscoveryInfoPublisher discovery{participant, "/" + config.ns, "sl_sensord"};
  std::uint64_t requests_rejected = 0;  // the request reader's sample-rejected count (status thread)

  // Publish-thread buffers of packed clouds (metres, decimated or valid
  // only), reused once no sample borrows them (beyond these, fresh ones).
  static constexpr std::size_t kPackBuffers = 8;
  std::vector<std::shared_ptr<std::vector<float>>> pack_buffers;
  // The image set published last (a set triangulated by two cameras gives
  // two results; it is published once). Publish thread only.
  pipeline::TimestampNs last_set_stamp_ns = -1;

  // The compressed images are encoded on a thread of their own: publish()
  // hands over copies of the images and goes on. At most one scan's images
  // wait; a newer scan's replace them, and each scan whose images were not
  // compressed (replaced, or the encoding failed) is counted.
  BoundedQueue<std::function<void()>> encode_jobs{1};
  std::atomic<std::uint64_t> encodings_failed{0};
  std::atomic<bool> encoder_stopping{false};
  std::thread encoder;  // started last in the constructor, joined first (~Impl)

  ~Impl() {
    encoder_stopping = true;
    encode_jobs.close();
    if (encoder.joinable()) encoder.join();
  }
  void encodeLoop() {
    while (!encoder_stopping) {
      std::optional<std::function<void()>> job = encode_jobs.pop(std::chrono::milliseconds(200));
      if (!job) continue;
      try {
        (*job)();
      } catch (const std::exception& e) {
        ++encodings_failed;
        logWarning(std::string("compressed images not published: ") + e.what());
      }
    }
  }
  std::uint64_t imagesNotCompressed() const { return encode_jobs.dropped() + encodings_failed.load(); }

  EdgeCounters edgeCounters();
  void publishStatus(const EngineStatus& s, const std::vector<std::string>& patterns);
  void publishDiagnostics(const EngineStatus& s);
  void serveRequests(CommandTarget& target);
};

void DdsBridge::Impl::publishDiagnostics(const EngineStatus& status) {
  const EdgeCounters edge = edgeCounters();
  DiagnosticInputs in;
  in.node_name = "sl_sensord";
  for (const auto& c : cameras) in.camera_ids.push_back(c.id);
  in.requests = edge.requests;
  in.writes_timed_out = edge.writes_timed_out;
  in.images_not_compressed = edge.images_not_compressed;
  in.clouds_lost_to_readers = edge.clouds_lost_to_readers;
  in.points_readers = edge.points_readers;
  diagnostics.publish(diagnosticsOf(status, in), pipeline::systemClockNs());
}

EdgeCounters DdsBridge::Impl::edgeCounters() {
  EdgeCounters c;
  c.requests = dispatcher.counters();
  c.replies_timed_out = dispatcher.repliesTimedOut();
  c.requests_malformed = malformed.count() + services.notServed();
  c.writes_timed_out = writes_timed_out.load();
  c.images_not_compressed = imagesNotCompressed();
  // Samples the full request reader refused (reading the status resets its
  // change count).
  dds_sample_rejected_status_t rejected{};
  if (dds_get_sample_rejected_status(request_reader.handle(), &rejected) == DDS_RETCODE_OK)
    requests_rejected += rejected.total_count_change;
  c.requests_rejected = requests_rejected;
  if (points_acks) {
    c.clouds_lost_to_readers = points_acks->lost();
    c.points_readers = points_acks->readers();
  }
  return c;
}

void DdsBridge::Impl::publishStatus(const EngineStatus& s, const std::vector<std::string>& patterns) {
  status_writer.write(StatusMessage(s, patterns, edgeCounters(), pipeline::systemClockNs()).sample());
}

// Takes every waiting request and answers it (or counts it as not answered).
void DdsBridge::Impl::serveRequests(CommandTarget& target) {
  for (;;) {
    dds::Loan<Request> requests = request_reader.take(16);
    if (requests.empty()) return;
    for (std::size_t i = 0; i < requests.size(); ++i) {
      if (!requests.isValid(i)) continue;
      const std::int64_t now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                      std::chrono::steady_clock::now().time_since_epoch())
                                      .count();
      const SenderId sender =
          origins.senderOf(request_reader.handle(), requests.info(i).publication_handle);
      const std::optional<ReplyValues> reply = dispatcher.dispatch(requests[i], sender, target, now_ns);
      if (!reply) continue;
      const ReplyMessage message(reply->client_id, reply->request_id, reply->result, reply->patterns,
                                 reply->detail);
      dispatcher.replied(reply_writer.write(message.sample()));
    }
  }
}

DdsBridge::DdsBridge(const DdsConfig& config, const std::string& camera_id,
                     const pipeline::CameraProjectorCalibration& calibration,
                     const std::map<std::string, pipeline::CameraProjectorCalibration>& other_cameras)
    : impl_(std::make_unique<Impl>(config, camera_id, calibration, other_cameras)) {}
DdsBridge::~DdsBridge() = default;

ResultContents DdsBridge::resultContents() const {
  const DdsConfig& c = impl_->config;
  // A cloud published from its own points and sent in place by a reliable
  // writer is kept until its readers acknowledged it.
  return {CloudUnit::kMetres, c.publish_projector_maps,
          impl_->points_writer.borrowing() && c.points_qos.reliable && packsInPlace(c.points_layout, 1.0),
          c.points_layout.confidence, c.points_layout.normals, c.points_normal_step};
}

void DdsBridge::publish(const ScanResult& result) {
  Impl& d = *impl_;
  auto count = [&d](bool written) {
    if (!written) ++d.writes_timed_out;
  };
  if (result.cloud) {
    // Triangulated in metres (resultContents()) and sent whole, the cloud's
    // points are the message's data; else one pass packs them.
    // The sample keeps what its data is in: the cloud or the buffer.
    const bool in_place = packsInPlace(d.config.points_layout, result.cloud_unit_m);
    std::shared_ptr<std::vector<float>> buffer = in_place ? nullptr : d.packBuffer();
    std::vector<float> unused;
    const PackedCloud packed = packCloud(*result.cloud, result.cloud_unit_m, d.config.points_layout,
                                         buffer ? *buffer : unused, result.quality.get());
    std::shared_ptr<const void> owner = result.cloud;
    if (buffer) owner = std::move(buffer);
    const bool written = d.points_writer.write(
        CloudMessage(packed, result.cloud->stamp_ns, d.frame_ids.of(result.camera_id)).sample(),
        std::move(owner));
    count(written);
    if (written && d.points_acks) d.points_acks->written();
  }
  // After the cloud, which then does not wait for the set's serialization;
  // a set triangulated by two cameras gives two results and is sent once.
  if (d.config.publish_image_sets && result.images &&
      result.images->trigger_stamp_ns != d.last_set_stamp_ns) {
    std::vector<std::string> frames;
    for (const auto& camera : result.images->cameras) frames.push_back(d.frame_ids.of(camera.camera_id));
    count(d.sets_writer.write(ImageSetMessage(*result.images, std::move(frames)).sample()));
    d.last_set_stamp_ns = result.images->trigger_stamp_ns;
  }
  if (d.config.publish_projector_maps && result.maps)
    count(d.maps_writer.write(
        MapsMessage(*result.maps, result.pattern, result.scan_index, d.config.frame_id).sample()));
  if (d.config.publish_images && result.cloud) {
    const std::string frame_id = d.frame_ids.of(result.camera_id);
    const ScanImages images(*result.cloud, result.cloud_unit_m, result.bit_depth, frame_id);
    count(d.depth_writer.write(images.depth()));
    count(d.shading_writer.write(images.shading()));
    // Compressed siblings cost an encoding: only for matched readers, on
    // the encoder thread, from copies.
    std::shared_ptr<const OwnedImage> shading_copy, depth_copy;
    if (d.shading_png_writer.matchedReaders() > 0)
      shading_copy = std::make_shared<const OwnedImage>(images.shading());
    // camera_info describes the first camera (whose frame is dds.frame_id);
    // images of other cameras carry their own frame_id and no camera_info
    // (nor a rectified depth image: the bridge has the first camera's model).
    const pipeline::TimestampNs stamp = result.cloud->stamp_ns;
    if (d.frame_ids.isFirst(result.camera_id)) {
      const CameraInfoMessage raw_info(d.camera, stamp, frame_id);
      d.info_writer.write(raw_info.sample());
      d.shading_info_writer.write(raw_info.sample());
      if (d.rectifier && result.cloud->width == d.rectifier->width() &&
          result.cloud->height == d.rectifier->height()) {
        const RectifiedDepthMessage rectified(images.depthValues(), *d.rectifier, stamp, frame_id);
        count(d.depth_rect_writer.write(rectified.sample()));
        if (d.depth_png_writer.matchedReaders() > 0)
          depth_copy = std::make_shared<const OwnedImage>(rectified.sample());
        d.depth_info_writer.write(CameraInfoMessage(d.camera, stamp, frame_id, true).sample());
      }
    }
    if (shading_copy || depth_copy) {
      d.encode_jobs.push([&d, shading_copy, depth_copy] {
        auto count_write = [&d](bool written) {
          if (!written) ++d.writes_timed_out;
        };
        if (shading_copy)
          count_write(d.shading_png_writer.write(CompressedPngMessage(shading_copy->sample(), kPngLevel).sample()));
        if (depth_copy)
          count_write(d.depth_png_writer.write(CompressedDepthMessage(depth_copy->sample(), kPngLevel).sample()));
      });
    }
  }
}

void DdsBridge::serve(ScanEngine& engine) {
  Impl& d = *impl_;
  EngineCommands target(engine);
  using Clock = std::chrono::steady_clock;
  std::uint64_t published_version = ~std::uint64_t{0};
  Clock::time_point next_periodic = Clock::now();
  Clock::time_point next_diagnostics = Clock::now();
  const std::vector<std::string> patterns = engine.patterns();
  // Adaptive scanning: the robot's velocity, polled with the requests (at
  // least every 100 ms).
  std::optional<VelocityInput> velocity;
  if (engine.config().adaptive.enabled) {
    velocity.emplace(d.participant, engine.config().adaptive);
    d.discovery.publish();  // with the new reader
  }
  while (!d.stopping) {
    d.waitset.wait(DDS_MSECS(100));
    d.serveRequests(target);
    if (velocity) velocity->forward(engine);
    d.services.serve(d.dispatcher, target, engine.status().pattern);
    const EngineStatus status = engine.status();
    if (status.version != published_version || Clock::now() >= next_periodic) {
      d.publishStatus(status, patterns);
      published_version = status.version;
      const auto period = std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(d.status_period_s.load()));
      next_periodic = Clock::now() + period;
    }
    // /diagnostics at 1 Hz, whether or not anyone reads it.
    if (Clock::now() >= next_diagnostics) {
      d.publishDiagnostics(status);
      next_diagnostics += std::chrono::seconds(1);
      if (next_diagnostics < Clock::now()) next_diagnostics = Clock::now() + std::chrono::seconds(1);
    }
  }
}

void DdsBridge::setStatusPeriod(double seconds) { impl_->status_period_s = seconds; }

void DdsBridge::stop() {
  impl_->stopping = true;
  impl_->wake.trigger();
}

}  // namespace sl::daemon
