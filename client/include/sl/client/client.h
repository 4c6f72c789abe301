// A client of a running sl_sensord over DDS: sends command requests, waits
// for the matching reply, receives point clouds and status. Used by slctl and
// the end-to-end tests.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sl/client/commands.h"
#include "sl/client/status_fields.h"
#include "sl/pipeline/types.h"

namespace sl::client {

struct ClientOptions {
  int domain_id = 0;
  std::string ns = "sl";
  bool subscribe_points = true;
};

struct CommandReplyInfo {
  bool accepted = false;
  CommandResult::Code code = CommandResult::Code::kOk;
  std::string reason;
  std::vector<std::string> patterns;
  std::string detail;  // kGetConfig: the daemon's configuration text
};

// A matched reader of the points topic (sl_msgs/Status.idl PointsReader).
struct PointsReaderInfo {
  std::string guid;
  bool reliable = true;
  bool acknowledging = true;
  std::uint64_t clouds_lost = 0;
};

struct StatusInfo {
  ScanState state = ScanState::kIdle;
  std::string pattern;
  // The engine's counters and measurements (status_fields.h).
  SL_STATUS_ENGINE_FIELDS(SL_STATUS_DECLARE_FIELD)
  std::uint64_t sets_dropped = 0;  // the engine's drops + writes_timed_out
  std::uint64_t writes_timed_out = 0;
  std::string recording;
  std::string last_error;
  std::vector<std::string> patterns;
  pipeline::TimestampNs stamp_ns = 0;
  TriggerMode trigger = TriggerMode::kHardware;
  std::vector<std::string> cameras;
  bool motion_compensation = false;
  pipeline::TimestampNs start_at_ns = 0;  // kWaiting: when scanning starts
  // Requests since start-up (see sl_msgs/Status.msg).
  std::uint64_t requests_received = 0, requests_answered = 0, requests_rate_limited = 0,
                requests_invalid = 0, replies_timed_out = 0, requests_malformed = 0;
  std::string degraded_reason;        // kDegraded: the cause
  pipeline::TimestampNs last_error_ns = 0;  // when last_error was reported
  std::uint64_t requests_rejected = 0;  // refusals of the full request reader
  std::uint64_t clouds_lost_to_readers = 0;
  std::vector<PointsReaderInfo> points_readers;
  std::uint64_t images_not_compressed = 0;  // see sl_msgs/Status.msg (edge counter)
  // Adaptive scanning (EngineStatus): mode ("" = off) and why; switches in status_fields.h.
  std::string adaptive_mode, adaptive_reason;
};

enum class Command { kStart, kStop, kSetPattern, kListPatterns, kGetConfig };

// Thread-compatible. Each client has a random id; replies to other clients
// are ignored.
class SensorClient {
 public:
  // Throws sl::dds::Error if DDS cannot be set up.
  explicit SensorClient(const ClientOptions& options);
  ~SensorClient();

  const std::string& clientId() const;

  // Waits until the daemon's request reader (and, if subscribed, its cloud
  // writer) is discovered. False on timeout: no daemon on this domain/ns.
  bool waitForDaemon(std::chrono::milliseconds timeout);

  // Sends a request and waits for its reply; nullopt on timeout.
  // `recording`: with kStart, also record the image sets under that name.
  std::optional<CommandReplyInfo> request(Command command, const std::string& pattern, int count,
                                          std::chrono::milliseconds timeout,
                                          const std::string& recording = "");
  // A start request with options (see StartRequest); nullopt on timeout.
  std::optional<CommandReplyInfo> start(const StartRequest& request,
                                        std::chrono::milliseconds timeout);

  // Next point cloud stamped at or after `not_before_ns`, converted back to
  // the pipeline type (mm); nullopt on timeout.
  std::optional<pipeline::PointCloud> receiveCloud(pipeline::TimestampNs not_before_ns,
                                                   std::chrono::milliseconds timeout);

  // Latest status (transient-local: available right after discovery).
  std::optional<StatusInfo> status(std::chrono::milliseconds timeout);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::client
