// The request state machine of the scan engine: idle -> (waiting ->)
// scanning -> idle / error; begin, launch, pattern switches at sequence
// boundaries, delayed starts, the end of a request. It drives the projector
// and the recorder and tells the grouping thread about every schedule change
// (ScheduleEvent); it starts no threads: the engine's control thread calls
// serviceTimers(), its output thread countScan() / finishIfComplete().
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "engine/schedule_events.h"
#include "recorder.h"
#include "sl/daemon/bounded_queue.h"
#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"
#include "sl/drivers/projector.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::client::ScanState;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;

// Thread-safe: one mutex guards every member below it; the generation is an
// atomic so that the data threads can tag and filter without the mutex.
class RequestControl {
 public:
  using Clock = std::chrono::steady_clock;

  struct Links {
    std::shared_ptr<drivers::Projector> projector;
    Recorder* recorder = nullptr;
    BoundedQueue<ScheduleEvent>* schedule = nullptr;  // to the grouping thread
    std::map<std::string, std::vector<std::string>> pattern_cameras;
    std::vector<std::string> camera_ids;
    std::string software_unsupported;  // "" = the devices can be software-triggered
    // The latest trigger grouped for the running pattern (0: none yet).
    std::function<pipeline::TimestampNs()> last_trigger_ns;
    // True once every camera delivered a frame stamped at or after the time.
    std::function<bool(pipeline::TimestampNs)> cameras_reached;
  };

  RequestControl(const DaemonConfig& config, Links links);

  CommandResult start(const StartRequest& request);
  CommandResult stop();
  CommandResult selectPattern(const std::string& name);

  // Control thread: begins a waiting request at its time, or carries out a
  // pending pattern switch at its boundary (waiting at most until the next
  // step is due). False when neither is pending.
  bool serviceTimers();
  // Waits up to `timeout` for a request to change (start, stop, switch).
  void waitForChange(std::chrono::milliseconds timeout);

  // A software-triggered request in progress.
  struct SoftwareRun {
    std::uint64_t generation = 0;
    std::string pattern;  // read at each sequence boundary
    int frame_count = 0;
    std::uint64_t scans_requested = 0;  // 0 = continuous
    // The cameras to trigger: those that triangulate the pattern for the
    // request and its intensity camera; every camera while recording (a
    // recording keeps all images of the set).
    std::vector<std::string> cameras;
  };
  std::optional<SoftwareRun> softwareRun() const;

  // Output thread: counts a scan of `generation`; its 1-based index within
  // the request, or nullopt when it belongs to no running request.
  std::optional<std::uint64_t> countScan(std::uint64_t generation);
  // Ends the request of `generation` once its last scan was published.
  void finishIfComplete(std::uint64_t generation);
  // Ends a finite request that missed its deadline (image sets were lost),
  // unless `sets_in_flight`: sets grouped but not yet published (queued or
  // being processed) are late, not lost, and may still complete it.
  void checkDeadline(bool sets_in_flight);
  // Ends the request of `generation` (if still current) with an error.
  void endRequest(std::uint64_t generation, const std::string& error);

  // The latest error, with the time and what it came from ("camera:<id>",
  // "trigger", "health", "reload", "" = other); a repeat of the same message
  // refreshes its time and count without a new status version.
  void reportError(const std::string& message, const std::string& source = "");
  // Clears last_error if its source starts with `source_prefix` (non-empty).
  void clearError(const std::string& source_prefix);
  // What the health check needs of the running request.
  struct Health {
    bool scanning = false;
    TriggerMode trigger = TriggerMode::kHardware;
    Clock::time_point since;  // when the scan began
    double sequence_s = 0;    // expected time per sequence
    std::uint64_t scans_requested = 0;  // 0 = continuous
  };
  Health health() const;
  // Output thread: the cause of a degraded scan ("" = healthy). A change is
  // logged and published; entering puts it into last_error, leaving clears
  // that again. Ignored when not scanning.
  void setDegraded(const std::string& cause);
  // Bumps the status version (a change worth publishing).
  void touch();

  std::uint64_t generation() const { return generation_.load(); }
  std::shared_ptr<const RequestOptions> options() const;
  // The cameras triangulating `pattern` under `options`.
  std::vector<std::string> camerasFor(const std::string& pattern, const RequestOptions& options) const;
  // State, pattern, scan counts, version, last error and request options.
  void fillStatus(EngineStatus& status) const;

  // Called once by the engine's destructor: wakes waiters for good.
  void shutDown();

 private:
  void beginLocked();
  void launchLocked(const std::string& name, int frame_count, int count);
  void switchLocked();
  bool switchTimeLocked(pipeline::TimestampNs now);
  void noteSwitchDelayedLocked();
  void finishLocked(const std::string& error);
  // How late a finite request's last images may come before its sets count
  // as lost: as long as the grouping waits for a sequence's frames
  // (synchroniser.max_age_s, 2 s by default).
  double lateS() const { return config_.synchroniser.max_age_ns * 1e-9; }
  void tellSchedule(ScheduleEvent event) { links_.schedule->push(std::move(event)); }

  const DaemonConfig& config_;
  Links links_;
  std::atomic<std::uint64_t> generation_{0};  // bumped at every begin and end

  mutable std::mutex mutex_;
  std::condition_variable changed_;  // with mutex_
  bool shut_down_ = false;
  std::string current_pattern_;
  ScanState state_ = ScanState::kIdle;
  std::uint64_t scans_requested_ = 0;
  std::uint64_t scans_done_ = 0;
  std::uint64_t status_version_ = 0;
  std::string last_error_;
  std::string error_source_;             // of last_error_
  pipeline::TimestampNs last_error_ns_ = 0;
  std::uint64_t errors_reported_ = 0;
  std::string degraded_reason_;          // "" = healthy (or not scanning)
  Clock::time_point degraded_since_;
  Clock::time_point scanning_since_;
  void setErrorLocked(const std::string& message, const std::string& source);
  std::string recording_;  // the recording in progress ("" = none)
  TriggerMode trigger_;    // of the current (or last) request
  std::shared_ptr<const RequestOptions> options_ = std::make_shared<RequestOptions>();
  // kWaiting: the request begins at launch_at_ns_ (system clock).
  pipeline::TimestampNs launch_at_ns_ = 0;
  int pending_count_ = 0;
  // When the running projector schedule was started (system clock): triggers
  // stamped before it are an earlier schedule's.
  pipeline::TimestampNs schedule_start_ns_ = 0;
  // A pattern switch of a continuous hardware-triggered scan, carried out at
  // switch_at_ns_, the end of a complete sequence of the running schedule
  // ("" = none; switch_at_ns_ 0 = not decided before its first trigger).
  // switch_replaced_: a later request replaced the pattern (a storm).
  std::string switch_pattern_;
  pipeline::TimestampNs switch_at_ns_ = 0;
  bool switch_replaced_ = false;
  // After the projector stopped at the boundary: the new schedule starts once
  // every camera delivered the old pattern's last frame (a restart may
  // discard frames not yet read out), or at drain_until_ at the latest.
  bool switch_draining_ = false;
  Clock::time_point drain_until_;
  // A finite request that has not delivered every scan by then ends with an
  // error (frames were lost).
  Clock::time_point deadline_ = Clock::time_point::max();
  double sequence_s_ = 0;  // expected time per sequence of the request
};

}  // namespace sl::daemon
