// Who wrote a request sample, as DDS tells it (private to daemon/): the
// instance handle of the writer's participant. A client chooses its
// client_id freely, but a new sender costs a new DDS participant (discovery,
// and under DDS Security an identity), so the rate limit is kept per sender
// (RequestGuard::admit). Not thread-safe: one per request loop.
#pragma once

#include <cstdint>
#include <unordered_map>

#include <dds/dds.h>

namespace sl::daemon {

class RequestOrigins {
 public:
  // The participant of the writer `publication` matched by `reader`
  // (dds_sample_info_t::publication_handle). A writer no longer matched is
  // its own sender (its publication handle), never sender 0 shared with
  // others.
  std::uint64_t senderOf(dds_entity_t reader, dds_instance_handle_t publication);

 private:
  // Writers seen (publication handle -> participant handle); forgotten all
  // at once beyond kMaxWriters (a lookup is a few microseconds).
  static constexpr std::size_t kMaxWriters = 1024;
  std::unordered_map<dds_instance_handle_t, std::uint64_t> participants_;
};

}  // namespace sl::daemon
