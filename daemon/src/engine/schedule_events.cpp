#include "engine/schedule_events.h"

namespace sl::daemon {

void applyScheduleEvent(const ScheduleEvent& event, std::uint64_t& active,
                        pipeline::ScheduleSynchroniser& grouping) {
  if (const auto* run = std::get_if<RunStarted>(&event.change)) {
    active = event.generation;
    grouping.startRun(run->pattern, run->frame_count, run->not_before_ns);
  } else if (const auto* next = std::get_if<PatternSwitched>(&event.change)) {
    if (event.generation == active) {
      grouping.switchPattern(next->pattern, next->frame_count, next->not_before_ns, next->boundary_ns);
    } else {
      active = event.generation;
      grouping.startRun(next->pattern, next->frame_count, next->not_before_ns);
    }
  } else if (const auto* pending = std::get_if<SwitchPending>(&event.change)) {
    if (event.generation == active) grouping.holdFrom(pending->at_ns);
  } else if (const auto* end = std::get_if<RunEnded>(&event.change)) {
    if (event.generation == active) grouping.endRun(end->count_pending);
  }
}

}  // namespace sl::daemon
