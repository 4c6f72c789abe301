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
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "sl/drivers/trigger_source.h"

namespace sl::drivers {

namespace rosserial {

inline constexpr std::uint16_t kTopicPublisher = 0;   // TopicInfo of a publisher / topic request
inline constexpr std::uint16_t kTopicSubscriber = 1;  // TopicInfo of a subscriber
inline constexpr std::uint16_t kTopicLog = 7;         // rosserial_msgs/Log
inline constexpr std::uint16_t kTopicTime = 10;       // time request / std_msgs/Time reply
inline constexpr std::uint16_t kTopicTxStop = 11;     // host stops
inline constexpr std::size_t kMaxMessage = 4096;      // longer lengths are treated as corrupt

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
};

struct VersavisCounters {
  std::uint64_t triggers = 0;         // events returned
  std::uint64_t packets = 0;          // valid packets
  std::uint64_t garbage_bytes = 0;    // skipped bytes
  std::uint64_t checksum_errors = 0;  // packets with a bad length or message checksum
  std::uint64_t malformed = 0;        // valid packets whose message did not decode
  std::uint64_t time_requests = 0;    // time requests answered
  std::uint64_t topic_requests = 0;   // topic requests sent
  std::uint64_t connects = 0;         // successful opens of the device
  std::uint64_t disconnects = 0;      // hang-ups / read errors
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
  explicit VersavisTriggerSource(VersavisConfig config);
  ~VersavisTriggerSource() override;
  VersavisTriggerSource(const VersavisTriggerSource&) = delete;
  VersavisTriggerSource& operator=(const VersavisTriggerSource&) = delete;

  std::optional<TriggerEvent> next(std::chrono::milliseconds timeout) override;
  void stop() override;
  VersavisCounters counters() const;
  bool connected() const { return connected_.load(); }

 private:
  using Clock = std::chrono::steady_clock;
  bool tryOpen(std::string* error);
  void closeDevice();
  void sendTopicRequest();
  void writeAll(const std::vector<std::uint8_t>& bytes);
  void handle(const rosserial::Frame& frame);

  const VersavisConfig config_;
  int fd_ = -1;
  int wake_fd_ = -1;  // eventfd written by stop()
  std::atomic<bool> stopped_{false};
  std::atomic<bool> connected_{false};
  rosserial::FrameParser parser_;
  std::optional<std::uint16_t> trigger_topic_;
  std::optional<std::uint64_t> first_number_;
  Clock::time_point next_reconnect_{};
  Clock::time_point next_negotiation_{};
  std::deque<TriggerEvent> pending_;
  std::string pending_error_;
  mutable std::mutex counters_mutex_;
  VersavisCounters counters_;  // guarded by counters_mutex_
};

}  // namespace sl::drivers
