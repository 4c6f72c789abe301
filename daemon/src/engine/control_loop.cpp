#include "engine/control_loop.h"

#include <chrono>

namespace sl::daemon {

using namespace std::chrono_literals;

void ControlLoop::run(const std::atomic<bool>& running, Heartbeat& hb) {
  bool holding = false;  // the camera threads are parked
  while (running) {
    hb.beat();
    if (control_.serviceTimers()) continue;
    const std::optional<RequestControl::SoftwareRun> run = control_.softwareRun();
    if (!run) {
      if (holding) {
        software_.stop();
        gate_.release();
        holding = false;
        continue;
      }
      control_.waitForChange(100ms);
      continue;
    }
    const std::uint64_t gen = run->generation;
    if (software_.finished(gen, run->scans_requested)) {
      control_.waitForChange(100ms);  // all sets taken; the output thread ends the request
      continue;
    }
    if (!holding) {
      if (!gate_.hold(3s, [&] { hb.beat(); })) {
        gate_.release();
        control_.endRequest(gen, "software trigger: the camera threads did not pause");
        continue;
      }
      holding = true;
    }
    SoftwareRuns::Outcome outcome = software_.acquire(gen, run->pattern, run->frame_count, run->cameras, [&] {
      hb.beat();
      return !running || control_.generation() != gen;
    });
    statistics_.framesReceived(outcome.frames);
    if (outcome.set) sets_(gen, std::move(outcome.set));
    if (outcome.end_request) {
      control_.endRequest(gen, outcome.fault);
    } else if (!outcome.fault.empty()) {
      control_.reportError(outcome.fault);
    }
    const pipeline::SynchroniserCounters& counts = software_.counters();
    statistics_.setSoftwareGrouping({counts.frames_unmatched, counts.triggers_incomplete});
  }
  if (holding) gate_.release();
}

}  // namespace sl::daemon
