// What the daemon checks of a request before the engine sees it (private to
// daemon/): string and list sizes (refused with INVALID_OPTION, the value
// never echoed beyond a short prefix) and a rate limit per sender: a token
// bucket for each DDS participant that writes requests (request_origin.h),
// not for each self-declared client_id, so that 1,000 made-up ids from one
// participant share that participant's allowance and a client of another
// participant keeps its own. Beyond limits.max_clients senders (idle ones
// are forgotten first) the newcomers share one bucket. Counters feed the
// status topic: every request taken from DDS is either answered or counted
// here. Not thread-safe: used by the bridge's request loop only.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>

#include "msg_convert.h"
#include "sl/daemon/config.h"  // RequestLimits (dds.requests)

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;

struct RequestCounters {
  std::uint64_t received = 0;      // samples taken from the request reader
  std::uint64_t answered = 0;      // replies written
  std::uint64_t rate_limited = 0;  // not answered: the client exceeded its rate
  std::uint64_t invalid = 0;       // answered with INVALID_OPTION by the size checks
};

// Who wrote a request: the DDS instance handle of the writer's participant
// (RequestOrigins::senderOf), or any value a test picks.
using SenderId = std::uint64_t;

class RequestGuard {
 public:
  explicit RequestGuard(RequestLimits limits = {}) : limits_(limits) {}

  // The reason to refuse `request` for its sizes (empty: sizes fine). Names
  // the field, its length and at most 32 of its first bytes, log-safe.
  std::string checkSizes(const msg::Request& request) const;

  // True if `sender` may send a request now (takes one of its tokens).
  bool admit(SenderId sender, std::int64_t now_ns);

  // The reply already sent to (sender, client_id, request_id), if it is
  // among the last kRememberedReplies: a client's retry of a request whose
  // reply it missed gets the same answer instead of a second execution (and
  // another participant cannot pre-empt it by reusing its ids).
  using Answer = CommandResult;
  const Answer* repeated(SenderId sender, const std::string& client_id,
                         std::uint64_t request_id) const;
  void remember(SenderId sender, const std::string& client_id, std::uint64_t request_id,
                Answer answer);
  static constexpr std::size_t kRememberedReplies = 64;

  RequestCounters counters;
  const RequestLimits& limits() const { return limits_; }

 private:
  struct Bucket {
    double tokens = 0;
    std::int64_t updated_ns = 0;
  };
  bool take(Bucket& bucket, std::int64_t now_ns);

  RequestLimits limits_;
  std::unordered_map<SenderId, Bucket> buckets_;
  Bucket shared_;
  struct Remembered {
    SenderId sender = 0;
    std::string client_id;
    std::uint64_t request_id = 0;
    Answer answer;
  };
  std::deque<Remembered> replies_;
  bool shared_started_ = false;
};

// `text` cut to `max` bytes for a reply or log line, with the full length:
// "abc...(1048576 bytes)".
std::string excerpt(const char* text, std::size_t max = 32);

}  // namespace sl::daemon
