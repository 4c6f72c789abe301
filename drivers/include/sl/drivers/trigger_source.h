// Projector trigger times (the VersaVIS board on the real sensor): one event
// at the start of each pattern sequence.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>

#include "sl/pipeline/types.h"

namespace sl::drivers {

struct TriggerEvent {
  pipeline::TimestampNs stamp_ns = 0;  // trigger of the sequence's first pattern
  std::uint64_t sequence_index = 0;    // counter since start
};

// Implementations must be thread-safe for next() on the engine's trigger
// thread against stop() from the thread shutting the engine down, which
// must wake a waiting next().
class TriggerSource {
 public:
  virtual ~TriggerSource() = default;
  // Next trigger, or nullopt on timeout or after stop().
  virtual std::optional<TriggerEvent> next(std::chrono::milliseconds timeout) = 0;
  virtual void stop() = 0;  // wakes a blocked next()
};

}  // namespace sl::drivers
