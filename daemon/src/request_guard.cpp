#include "request_guard.h"

#include <algorithm>
#include <cstring>

#include "sl/daemon/log.h"

namespace sl::daemon {

std::string excerpt(const char* text, std::size_t max) {
  if (!text) return "";
  const std::size_t n = std::strlen(text);
  if (n <= max) return logSafe(text);
  return logSafe(std::string(text, max)) + "...(" + std::to_string(n) + " bytes)";
}

std::string RequestGuard::checkSizes(const msg::Request& request) const {
  auto check = [&](const char* field, const char* value) -> std::string {
    const std::size_t n = value ? std::strlen(value) : 0;
    if (n <= limits_.max_string) return "";
    return std::string(field) + " is " + std::to_string(n) + " bytes, more than " +
           std::to_string(limits_.max_string) + " ('" + excerpt(value) + "')";
  };
  for (const auto& [field, value] : {std::pair{"client_id", request.client_id},
                                     std::pair{"pattern", request.pattern},
                                     std::pair{"recording", request.recording}})
    if (std::string reason = check(field, value); !reason.empty()) return reason;
  if (request.cameras._length > limits_.max_cameras)
    return "cameras has " + std::to_string(request.cameras._length) + " entries, more than " +
           std::to_string(limits_.max_cameras);
  for (std::uint32_t i = 0; i < request.cameras._length; ++i)
    if (std::string reason = check("cameras entry", request.cameras._buffer[i]); !reason.empty())
      return reason;
  return "";
}

bool RequestGuard::take(Bucket& bucket, std::int64_t now_ns) {
  const double elapsed_s = std::max<std::int64_t>(0, now_ns - bucket.updated_ns) * 1e-9;
  bucket.tokens = std::min(limits_.burst, bucket.tokens + elapsed_s * limits_.rate_hz);
  bucket.updated_ns = now_ns;
  if (bucket.tokens < 1) return false;
  bucket.tokens -= 1;
  return true;
}

bool RequestGuard::admit(SenderId sender, std::int64_t now_ns) {
  auto it = buckets_.find(sender);
  if (it == buckets_.end()) {
    if (buckets_.size() >= limits_.max_clients) {
      // Forget clients whose bucket has refilled (idle for burst / rate s).
      const auto refill_ns = static_cast<std::int64_t>(limits_.burst / limits_.rate_hz * 1e9);
      for (auto i = buckets_.begin(); i != buckets_.end();)
        i = now_ns - i->second.updated_ns > refill_ns ? buckets_.erase(i) : std::next(i);
    }
    if (buckets_.size() >= limits_.max_clients) {
      if (!shared_started_) shared_ = {limits_.burst, now_ns}, shared_started_ = true;
      return take(shared_, now_ns);
    }
    it = buckets_.emplace(sender, Bucket{limits_.burst, now_ns}).first;
  }
  return take(it->second, now_ns);
}

const RequestGuard::Answer* RequestGuard::repeated(SenderId sender, const std::string& client_id,
                                                   std::uint64_t request_id) const {
  for (const auto& r : replies_)
    if (r.request_id == request_id && r.sender == sender && r.client_id == client_id)
      return &r.answer;
  return nullptr;
}

void RequestGuard::remember(SenderId sender, const std::string& client_id,
                            std::uint64_t request_id, Answer answer) {
  if (replies_.size() >= kRememberedReplies) replies_.pop_front();
  replies_.push_back({sender, client_id, request_id, std::move(answer)});
}

}  // namespace sl::daemon
