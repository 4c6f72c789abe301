// Projector trigger times from a VersaVIS board over its serial link
// (rosserial framing), as an sl::drivers::TriggerSource.
//
// rosserial wire format (rosserial "Serialization protocol", protocol
// version 2 / ROS Hydro and later): each packet is
//   0xFF sync | 0xFE protocol version | length LE (2) | length checksum |
//   topic id LE (2) | message (length bytes, ROS serialization) | checksum
// with length checksum = 255 - ((len_lo + len_hi) % 256) and message
// checksum = 255 - ((topic_lo + topic_hi + sum(message)) % 256).
// Topic negotiation: the host sends an empty message on topic id 0; the
// board answers with one rosserial_msgs/TopicInfo per publisher (on topic id
// 0) and subscriber (topic id 1), and asks for the time on topic id 10, which
// the host answers with std_msgs/Time (the board keeps publishing only while
// time requests are answered).
//
// What the VersaVIS firmware publishes (ethz-asl/versavis, firmware
// Camera.cpp): every trigger channel, the projector channel included (its
// topic contains "projector"), publishes versavis/TimeNumbered on
// "<channel topic>image_time", i.e. "/versavis/projector/image_time" in the
// SL sensor's configuration. TimeNumbered.msg is "time time, uint64 number":
// on the wire uint32 secs, uint32 nsecs, uint64 number (little endian), 16
// bytes. The time is the board's clock, which rosserial keeps synchronised to
// the host's time replies (here CLOCK_REALTIME, the clock of Frame::stamp_ns);
// `number` is the trigger counter of the channel.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <vector>

#include "sl/drivers/forwarding.h"
#include "sl/drivers/trigger_source.h"

namespace sl::drivers {

namespace rosserial {

inline constexpr std::uint16_t kTopicPublisher = 0;   // TopicInfo of a publisher / topic request
inline constexpr std::uint16_t kTopicSubscriber = 1;  // TopicInfo of a subscriber
inline constexpr std::uint16_t kTopicLog = 7;         // rosserial_msgs/Log
inline constexpr std::uint16_t kTopicTime = 10;       // time request / std_msgs/Time reply
inline constexpr std::uint16_t kTopicTxStop = 11;     // host stops
inline constexpr std::uint16_t kFirstUserTopic =
    100;  // rosserial_client: subscribers 100.., publishers 125..
inline constexpr std::size_t kMaxMessage = 4096;  // longer lengths are treated as corrupt

std::vector<std::uint8_t> encodeFrame(std::uint16_t topic_id,
                                      std::span<const std::uint8_t> message);

struct Frame {
  std::uint16_t topic_id = 0;
  std::vector<std::uint8_t> message;
};

// Incremental packet parser: feed() any bytes, next() returns complete,
// checksum-valid packets. Bytes that are not part of a valid packet are
// skipped (counted as garbage); a corrupt length or message checksum skips
// the sync byte and resynchronises on the next 0xFF. Thread-compatible.
class FrameParser {
 public:
  void feed(std::span<const std::uint8_t> bytes);
  std::optional<Frame> next();
  void clear() { buffer_.clear(); }
  std::uint64_t garbageBytes() const { return garbage_; }
  std::uint64_t checksumErrors() const { return checksum_errors_; }

 private:
  std::vector<std::uint8_t> buffer_;
  std::uint64_t garbage_ = 0;
  std::uint64_t checksum_errors_ = 0;
};

// rosserial_msgs/TopicInfo: uint16 topic_id, string topic_name, string
// message_type, string md5sum, int32 buffer_size (strings: uint32 length + bytes).
struct TopicInfo {
  std::uint16_t topic_id = 0;
  std::string topic_name, message_type, md5sum;
  std::int32_t buffer_size = 0;
};
std::vector<std::uint8_t> encodeTopicInfo(const TopicInfo& info);
std::optional<TopicInfo> decodeTopicInfo(std::span<const std::uint8_t> message);

// versavis/TimeNumbered (see the file comment).
struct TimeNumbered {
  std::uint32_t secs = 0, nsecs = 0;
  std::uint64_t number = 0;
};
inline constexpr const char* kTimeNumberedType = "versavis/TimeNumbered";
inline constexpr const char* kTimeNumberedMd5 = "a1a1eed10c75c0326a67a86fc18b029d";
std::vector<std::uint8_t> encodeTimeNumbered(const TimeNumbered& m);
std::optional<TimeNumbered> decodeTimeNumbered(std::span<const std::uint8_t> message);

// std_msgs/Time: uint32 secs, uint32 nsecs.
std::vector<std::uint8_t> encodeTime(std::int64_t stamp_ns);
std::optional<std::int64_t> decodeTime(std::span<const std::uint8_t> message);

// std_msgs/Bool: one byte (the board's /versavis/reset and camN/init
// subscribers).
inline constexpr const char* kBoolType = "std_msgs/Bool";
inline constexpr const char* kBoolMd5 = "8b94c1b53db61fb6aed406028ad6332a";
std::vector<std::uint8_t> encodeBool(bool value);
std::optional<bool> decodeBool(std::span<const std::uint8_t> message);

// rosserial_msgs/Log (topic id 7): uint8 level (0 debug, 1 info, 2 warn,
// 3 error, 4 fatal), string msg.
struct LogMessage {
  std::uint8_t level = 1;
  std::string text;
};
std::vector<std::uint8_t> encodeLog(const LogMessage& m);
std::optional<LogMessage> decodeLog(std::span<const std::uint8_t> message);

}  // namespace rosserial

struct VersavisConfig {
  std::string device = "/dev/versavis";  // serial device (udev symlink of the board)
  int baud = 250000;                     // the firmware's setBaud (USB CDC ignores it)
  std::string topic = "/versavis/projector/image_time";
  std::string message_type = rosserial::kTimeNumberedType;
  // Board triggers per pattern sequence: 1 when the board triggers the
  // projector once per sequence; N when it triggers every pattern (every Nth
  // trigger, counted from the first one received, starts a sequence).
  int triggers_per_sequence = 1;
  std::int64_t offset_ns = 0;  // added to every board stamp (trigger-to-exposure delay)
  std::chrono::milliseconds reconnect_interval{1000};  // retry opening a missing device
  std::chrono::milliseconds negotiation_retry{2000};   // resend the topic request
  // Board camera channels (topic prefixes as in the firmware's CAMn_TOPIC),
  // one per daemon camera in order; several cameras may share a channel.
  // Each channel publishes "<prefix>image_time" (one TimeNumbered per
  // trigger) and subscribes "<prefix>init": the firmware pulses the camera
  // at 1 Hz and publishes no projector time until it gets `true` there.
  // Empty: no handshake, camera stamps are used as they are.
  std::vector<std::string> camera_channels;
  // Camera frames matched to consecutive board camera times (same number
  // offset, arrival within max_arrival_delay) before init is sent.
  int init_matches = 2;
  std::chrono::milliseconds max_arrival_delay{100};
  // How long a camera frame waits for its board camera time.
  std::chrono::milliseconds restamp_wait{200};
  std::int64_t camera_offset_ns = 0;  // added to board camera times (exposure start)
  // Re-request the topics after this long without a time request from the
  // board (rosserial_python: 3 x its 5 s timeout), or on a packet with a
  // topic id that was not negotiated.
  std::chrono::milliseconds sync_timeout{15000};
  // No packet at all for this long: next() reports the board silent (once).
  std::chrono::milliseconds watchdog{3000};
  bool reset_at_start = true;  // publish /versavis/reset once the board subscribes it
  std::string reset_topic = "/versavis/reset";
  bool tx_stop_at_close = true;  // send rosserial's TX_STOP when closing
};

struct VersavisCounters {
  std::uint64_t triggers = 0;            // events returned
  std::uint64_t packets = 0;             // valid packets
  std::uint64_t garbage_bytes = 0;       // skipped bytes
  std::uint64_t checksum_errors = 0;     // packets with a bad length or message checksum
  std::uint64_t malformed = 0;           // valid packets whose message did not decode
  std::uint64_t time_requests = 0;       // time requests answered
  std::uint64_t topic_requests = 0;      // topic requests sent
  std::uint64_t connects = 0;            // successful opens of the device
  std::uint64_t disconnects = 0;         // hang-ups / read errors
  std::uint64_t renegotiations = 0;      // topic requests after lost sync or an unknown topic id
  std::uint64_t unknown_topics = 0;      // packets on a topic id that was not negotiated
  std::uint64_t md5_mismatches = 0;      // negotiated topics refused for their md5
  std::uint64_t log_messages = 0;        // rosserial_msgs/Log from the board
  std::uint64_t camera_times = 0;        // board camera times received (all channels)
  std::uint64_t inits_sent = 0;          // init true published to a camera channel
  std::uint64_t frames_restamped = 0;    // camera frames given their board trigger time
  std::uint64_t frames_unstamped = 0;    // frames dropped: no board time found for them
  std::uint64_t frames_before_init = 0;  // frames seen while the handshake matched
  std::uint64_t resets_sent = 0;
  std::uint64_t triggers_before_start = 0;  // dropped: received before the projector's start
  bool silent = false;                      // the watchdog fired and no packet came since
};

// Outcome of VersavisTriggerSource::restamp for one camera frame.
enum class RestampResult {
  kRestamped,  // stamp replaced by the board's trigger time
  kLearning,   // handshake in progress (frame keeps its stamp)
  kNoTime,     // initialised, but no board time for this frame: drop it
};

// Thread-safety: next() must be called from one thread at a time (the
// daemon's trigger thread); stop() and counters() may be called from any
// thread. No thread inside: next() does the serial I/O with poll().
//
// The constructor opens the device and throws std::runtime_error naming it if
// it cannot. A board that hangs up later is reported once by next() throwing
// ("board disconnected"); next() then reopens the device every
// reconnect_interval and negotiates the topics again.
class VersavisTriggerSource : public TriggerSource {
 public:
  // level: rosserial_msgs/Log level (0 debug .. 4 fatal); board log
  // messages and the driver's own notes (handshake, re-negotiation) go here.
  using Log = std::function<void(int level, const std::string& message)>;
  explicit VersavisTriggerSource(VersavisConfig config, Log log = {});
  ~VersavisTriggerSource() override;
  VersavisTriggerSource(const VersavisTriggerSource&) = delete;
  VersavisTriggerSource& operator=(const VersavisTriggerSource&) = delete;

  std::optional<TriggerEvent> next(std::chrono::milliseconds timeout) override;
  void stop() override;
  VersavisCounters counters() const;
  bool connected() const { return connected_.load(); }

  // Camera side (thread-safe; called by VersavisRestampCamera on a camera
  // thread while next() runs on the trigger thread). Matches a frame of
  // daemon camera `camera` (index into camera_channels) with the board
  // camera time of the same trigger and, once matched, writes that time
  // (+ camera_offset_ns) into `stamp_ns`. `arrival_ns` is when the frame
  // reached the host (system clock). Handshake: the board times that
  // arrived within max_arrival_delay before a frame give the number offset
  // (frame_id - board number); init_matches consecutive frames with the same
  // offset initialise the camera, and the channel's init topic gets `true`
  // (once per board session). A lost offset (kNoTime for init_matches frames
  // in a row) starts the matching again.
  RestampResult restamp(std::size_t camera, std::uint64_t frame_id, std::int64_t arrival_ns,
                        std::int64_t& stamp_ns);
  std::size_t cameraCount() const { return config_.camera_channels.size(); }
  // Projector triggers that reached the host before `host_ns` (system clock)
  // are dropped (counted in triggers_before_start): the projector was not
  // running for them. Thread-safe.
  void dropTriggersBefore(std::int64_t host_ns);
  bool cameraInitialised(std::size_t camera) const;

 private:
  using Clock = std::chrono::steady_clock;
  struct BoardTime {
    std::uint64_t number = 0;
    std::int64_t board_ns = 0;
    std::int64_t arrival_ns = 0;  // host system clock when the packet was read
  };
  struct Channel {  // one board camera channel
    std::string prefix;
    std::optional<std::uint16_t> time_topic, init_topic;
    std::deque<BoardTime> times;  // newest last, bounded
    bool init_sent = false;
  };
  struct CameraState {
    std::size_t channel = 0;
    bool initialised = false;
    std::optional<std::int64_t> offset;  // frame_id - board number
    int matches = 0, misses = 0;
  };
  bool tryOpen(std::string* error);
  void closeDevice();
  void sendTopicRequest();
  void resetSession();  // new board session: topics and handshake forgotten
  void writeAll(const std::vector<std::uint8_t>& bytes);
  void handle(const rosserial::Frame& frame);
  void handleTopicInfo(const rosserial::TopicInfo& info, bool subscriber);
  void note(int level, const std::string& message) const;
  void count(std::uint64_t VersavisCounters::*field, std::uint64_t n = 1);

  const VersavisConfig config_;
  const Log log_;
  int fd_ = -1;
  int wake_fd_ = -1;  // eventfd written by stop() and by restamp() (outgoing init)
  std::atomic<bool> stopped_{false};
  std::atomic<bool> connected_{false};
  rosserial::FrameParser parser_;
  std::optional<std::uint16_t> trigger_topic_;
  std::optional<std::uint64_t> first_number_;
  Clock::time_point next_reconnect_{};
  Clock::time_point next_negotiation_{};
  Clock::time_point last_time_request_{};  // sync: the board's last time request
  Clock::time_point last_packet_{};
  std::set<std::uint16_t> known_topics_;  // negotiated publisher ids
  bool reset_sent_ = false;               // once per process
  bool expect_hangup_ = false;            // after the reset: reconnect quietly
  bool rebooting_ = false;                // reopen retried every 100 ms meanwhile
  std::deque<TriggerEvent> pending_;
  std::deque<std::int64_t> pending_arrival_;  // host arrival of each pending event
  std::atomic<std::int64_t> drop_before_ns_{0};
  std::string pending_error_;
  mutable std::mutex counters_mutex_;
  VersavisCounters counters_;  // guarded by counters_mutex_
  // Camera side, guarded by cameras_mutex_ (restamp() waits on cameras_cv_).
  mutable std::mutex cameras_mutex_;
  std::condition_variable cameras_cv_;
  std::vector<Channel> channels_;
  std::vector<CameraState> cameras_;
  std::deque<std::vector<std::uint8_t>> outbox_;  // frames for the trigger thread to write
};

// Projector decorator of the VersaVIS hardware path: after each start() the
// trigger source drops the triggers that reached the host before it (their
// board stamps are on a clock up to ~100 ms off the host's, so the engine's
// host-clock start time cannot tell them apart). Thread-safety as the
// wrapped projector.
class VersavisStartTapProjector : public ForwardingProjector {
 public:
  VersavisStartTapProjector(std::shared_ptr<Projector> projector,
                            std::shared_ptr<VersavisTriggerSource> source)
      : ForwardingProjector(std::move(projector)), source_(std::move(source)) {}
  void start(int count) override;

 private:
  std::shared_ptr<VersavisTriggerSource> source_;
};

// Camera decorator of the VersaVIS hardware path: every frame gets the
// board's trigger time of its channel (VersavisTriggerSource::restamp), so
// frames and projector trigger times are on the board's clock from the
// first frame on, whatever the board's clock offset to the host. Frames
// seen during the handshake pass unchanged (the board publishes no
// projector times until it is done); frames for which no board time comes
// are dropped and counted (frames_unstamped). Thread-safety as the wrapped
// camera.
class VersavisRestampCamera : public ForwardingCamera {
 public:
  VersavisRestampCamera(std::shared_ptr<Camera> camera,
                        std::shared_ptr<VersavisTriggerSource> source, std::size_t index);
  std::optional<Frame> grab(std::chrono::milliseconds timeout) override;

 private:
  std::shared_ptr<VersavisTriggerSource> source_;
  std::size_t index_;
};

}  // namespace sl::drivers
