// Request dispatch (private to daemon/): one CommandRequest taken from DDS
// becomes one call on the sensor and one reply, or is counted as not
// answered. Owns the RequestGuard (sizes, rate limits, retries) and the
// request log lines; knows nothing of DDS entities, so it is tested with
// hand-made samples and a fake target (tests/daemon/test_messages.cpp).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "msg_convert.h"
#include "request_guard.h"
#include "sl/client/commands.h"
#include "sl/daemon/config.h"  // RequestLimits

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::client::StartRequest;

// What requests act on: the ScanEngine in the daemon.
class CommandTarget {
 public:
  virtual ~CommandTarget() = default;
  virtual CommandResult start(const StartRequest& request) = 0;
  virtual CommandResult stop() = 0;
  virtual CommandResult selectPattern(const std::string& pattern) = 0;
  virtual std::vector<std::string> patterns() const = 0;
  virtual std::string configText() const = 0;  // GET_CONFIG's detail
};

// The values of one reply (msg::ReplyMessage builds the sample).
struct ReplyValues {
  std::string client_id;  // cut to an excerpt when over the size limit
  std::uint64_t request_id = 0;
  CommandResult result;
  std::vector<std::string> patterns;  // every reply lists them
  std::string detail;                 // GET_CONFIG: the configuration text
};

// The START options of `request`; a value outside the IDL enums is named in
// `error` (the request is then refused with INVALID_OPTION).
StartRequest toStartRequest(const msg::Request& request, std::string& error);

// Not thread-safe: the bridge's request loop only.
class RequestDispatcher {
 public:
  explicit RequestDispatcher(const RequestLimits& limits) : guard_(limits) {}

  // Counts `request` as received and carries it out on `target`: the reply
  // to write, or nullopt when its sender (the writer's participant,
  // RequestOrigins) is over its rate limit (counted in rate_limited, logged
  // at most every 200 refusals). `now_ns`: a steady clock, for the rate
  // limit.
  std::optional<ReplyValues> dispatch(const msg::Request& request, SenderId sender,
                                      CommandTarget& target, std::int64_t now_ns);
  // Whether the reply to the last dispatched request was written (answered)
  // or timed out on the reliable writer (replies_timed_out).
  void replied(bool written);

  const RequestCounters& counters() const { return guard_.counters; }
  std::uint64_t repliesTimedOut() const { return replies_timed_out_; }

 private:
  CommandResult carryOut(const msg::Request& request, CommandTarget& target);

  RequestGuard guard_;
  std::uint64_t replies_timed_out_ = 0;
  std::uint64_t rate_limited_logged_ = 0;  // log again when rate_limited reaches this
};

}  // namespace sl::daemon
