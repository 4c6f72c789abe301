// What request control tells the grouping thread about the projector's
// schedule, and the per-request options the processing thread applies. Each
// event carries the request generation it belongs to; the grouping thread
// discards events of another generation than the running one.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "sl/pipeline/schedule_synchroniser.h"
#include "sl/pipeline/types.h"

namespace sl::daemon {

// Options of the current request that the processing thread applies per set.
struct RequestOptions {
  std::string cameras_pattern;       // the pattern `cameras` was given for
  std::vector<std::string> cameras;  // empty: the pattern's configured cameras
  std::optional<bool> motion_compensation;  // empty: as configured
};

// The projector starts a new request's schedule (ScheduleSynchroniser::startRun).
struct RunStarted {
  std::string pattern;
  int frame_count = 0;
  pipeline::TimestampNs not_before_ns = 0;
};
// A switch is pending at this sequence boundary (holdFrom); at_ns = max:
// the switch was cancelled.
struct SwitchPending {
  pipeline::TimestampNs at_ns = 0;
};
// The projector stopped at `boundary_ns` and starts `pattern` (switchPattern).
struct PatternSwitched {
  std::string pattern;
  int frame_count = 0;
  pipeline::TimestampNs not_before_ns = 0;
  pipeline::TimestampNs boundary_ns = 0;
};
// The request ended (endRun); count_pending when it ended with an error.
struct RunEnded {
  bool count_pending = false;
};

struct ScheduleEvent {
  std::uint64_t generation = 0;
  std::variant<RunStarted, SwitchPending, PatternSwitched, RunEnded> change;
};

// Applies `event` to the grouping of the generation `active` (the one whose
// schedule runs; a new run makes its generation active); events of other
// generations are ignored.
void applyScheduleEvent(const ScheduleEvent& event, std::uint64_t& active,
                        pipeline::ScheduleSynchroniser& grouping);

}  // namespace sl::daemon
