// The scan engine's threads and the queues between them; each thread runs
// one stage (engine/*.h, pipeline stages) and owns it.
#include "sl/daemon/scan_engine.h"

#include <algorithm>
#include <cstdio>
#include <chrono>
#include <thread>
#include <utility>
#include <variant>

#include "engine/request_control.h"
#include "engine/schedule_events.h"
#include "engine/set_processor.h"
#include "engine/start_validation.h"
#include "engine/software_trigger.h"
#include "engine/statistics.h"
#include "engine/thread_health.h"
#include "recorder.h"
#include "sl/daemon/bounded_queue.h"
#include "sl/pipeline/schedule_synchroniser.h"

namespace sl::daemon {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

// What the camera and trigger threads hand to the grouping thread, tagged
// with the request generation current when it arrived.
struct FrameEvent {
  std::size_t camera = 0;
  pipeline::Frame frame;
};
struct TriggerEvent {
  pipeline::TimestampNs stamp_ns = 0;
};
struct InputEvent {
  std::uint64_t generation = 0;
  std::variant<FrameEvent, TriggerEvent> payload;
};
struct SetItem {
  std::uint64_t generation = 0;
  std::shared_ptr<const pipeline::ImageSet> set;
};
struct ResultItem {
  std::uint64_t generation = 0;
  std::vector<ScanResult> results;  // one per triangulating camera, same scan
  // System clock: the sequence's last exposure, processing start and end.
  pipeline::TimestampNs exposed_ns = 0, processing_ns = 0, processed_ns = 0;
};

// Queue sizes and policies. Frames and triggers: enough for a few sequences
// of the longest pattern, the oldest dropped (frames_overflow). Schedule
// changes: never dropped; request control waits for room (the grouping
// thread takes them at least every 50 ms). Sets and results: the configured
// depth, the oldest dropped (sets_overflow).
constexpr std::size_t kInputQueueCapacity = 64;
constexpr std::size_t kScheduleQueueCapacity = 64;

RecordingQuota quotaOf(const RuntimeConfig& r) {
  constexpr std::uint64_t kMB = 1000 * 1000;
  return {r.recording_max_mb * kMB, r.recording_max_sets, r.recording_min_free_mb * kMB};
}

std::vector<std::string> idsOf(const EngineDevices& devices) {
  std::vector<std::string> ids;
  for (const auto& c : devices.cameras) ids.push_back(c->id());
  return ids;
}

}  // namespace

struct ScanEngine::Impl {
  Impl(const DaemonConfig& config, EngineDevices devices, OutputCallback output, ResultContents contents)
      : config(config),
        devices(std::move(devices)),
        output(std::move(output)),
        camera_ids(idsOf(this->devices)),
        events(kInputQueueCapacity),
        schedule(kScheduleQueueCapacity, Overflow::kWaitForRoom),
        sets(config.runtime.queue_depth),
        results(config.runtime.queue_depth),
        processing_config(processingConfigOf(config, camera_ids,
                                             contents.cloud_unit == CloudUnit::kMetres ? 1000.0 : 1.0,
                                             contents.projector_maps)),
        processor(processing_config),
        motion_enabled(processing_config.motion_enabled),
        software(this->devices.cameras, this->devices.projector, config.software_trigger),
        last_frame_ns(camera_ids.size()),
        camera_seen(camera_ids.size()),
        camera_errors(camera_ids.size()),
        control(config, linksOf(config)) {
    for (auto& camera : this->devices.cameras) camera->start();
  }

  RequestControl::Links linksOf(const DaemonConfig& config) {
    RequestControl::Links links;
    links.pattern_cameras = checkedPatternCameras(config, camera_ids, processing_config.calibrations);
    links.software_unsupported = software.unsupportedReason();
    if (config.runtime.trigger == TriggerMode::kSoftware && !links.software_unsupported.empty())
      throw std::runtime_error(config.source_path + ": runtime.trigger is software, but " +
                               links.software_unsupported);
    links.projector = devices.projector;
    links.recorder = &recorder;
    links.schedule = &schedule;
    links.camera_ids = camera_ids;
    links.last_trigger_ns = [this] { return last_trigger_ns.load(); };
    links.cameras_reached = [this](pipeline::TimestampNs t) {
      return std::all_of(last_frame_ns.begin(), last_frame_ns.end(),
                         [t](const auto& stamp) { return stamp.load() >= t; });
    };
    return links;
  }

  // --- configuration and devices (immutable after construction) ---
  const DaemonConfig config;
  EngineDevices devices;
  OutputCallback output;
  const std::vector<std::string> camera_ids;  // in synchroniser order

  // --- queues between the threads (policies above) ---
  BoundedQueue<InputEvent> events;        // camera + trigger threads -> grouping
  BoundedQueue<ScheduleEvent> schedule;   // request control -> grouping
  BoundedQueue<SetItem> sets;             // grouping, control (software) -> processing
  BoundedQueue<ResultItem> results;       // processing -> output

  Recorder recorder{8, quotaOf(config.runtime)};  // writes the sets of requests that record (own thread)
  EngineStatistics statistics;

  // --- stages, each used by one thread only ---
  const ProcessingConfig processing_config;  // as loaded
  SetProcessor processor;                    // processing thread
  std::atomic<bool> motion_enabled;          // as configured or reloaded; for the status
  SoftwareRuns software;                     // control thread
  // Settings from a config reload, applied by the processing thread before
  // its next set (the flag avoids taking the mutex per set).
  std::mutex settings_mutex;
  std::optional<DaemonConfig> pending_settings;  // guarded by settings_mutex
  std::atomic<bool> settings_pending{false};

  // Written by the grouping / camera threads, read by request control.
  std::atomic<pipeline::TimestampNs> last_trigger_ns{0};
  std::vector<std::atomic<pipeline::TimestampNs>> last_frame_ns;  // per camera

  // For the health check (output thread): when each camera last delivered a
  // frame and the trigger source a trigger (steady clock, 0 = never), and
  // each camera's latest grab error since its last frame.
  std::vector<std::atomic<std::int64_t>> camera_seen;
  std::atomic<std::int64_t> trigger_seen{0};
  std::mutex health_mutex;
  std::vector<std::string> camera_errors;  // guarded by health_mutex
  std::string trigger_error;               // guarded by health_mutex
  Clock::time_point next_health_check;     // output thread

  RequestControl control;  // last: its links point at the members above

  CameraGate gate{camera_ids.size()};  // parks the camera threads (software trigger)

  std::atomic<bool> running{true};
  std::vector<Heartbeat> heartbeats;  // sized before threads start
  std::vector<std::thread> threads;

  void cameraLoop(std::size_t index, Heartbeat& hb);
  void triggerLoop(Heartbeat& hb);
  void groupLoop(Heartbeat& hb);
  void processLoop(Heartbeat& hb);
  void outputLoop(Heartbeat& hb);
  void controlLoop(Heartbeat& hb);
  void applyPendingSettings();
  void checkHealth();
  std::string degradedCause();
};

namespace {
std::int64_t steadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}
std::string secondsText(double s) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f", s);
  return text;
}
}  // namespace

void ScanEngine::Impl::cameraLoop(std::size_t index, Heartbeat& hb) {
  auto& camera = *devices.cameras[index];
  while (running) {
    hb.beat();
    if (gate.parkIfHeld([&] { hb.beat(); }, [&] { return running.load(); })) continue;
    std::optional<pipeline::Frame> frame;
    try {
      frame = camera.grab(100ms);
    } catch (const std::exception& e) {
      const std::string message = "camera '" + camera.id() + "': " + e.what();
      {
        std::lock_guard lock(health_mutex);
        camera_errors[index] = e.what();
      }
      control.reportError(message, "camera:" + camera.id());
      std::this_thread::sleep_for(100ms);
      continue;
    }
    if (frame) {
      camera_seen[index] = steadyNowNs();
      bool had_error = false;
      {
        std::lock_guard lock(health_mutex);
        had_error = !camera_errors[index].empty();
        camera_errors[index].clear();
      }
      if (had_error) control.clearError("camera:" + camera.id());
      statistics.framesReceived(1);
      last_frame_ns[index] = frame->stamp_ns;
      events.push({control.generation(), FrameEvent{index, std::move(*frame)}});
    }
  }
}

void ScanEngine::Impl::triggerLoop(Heartbeat& hb) {
  while (running) {
    hb.beat();
    std::optional<drivers::TriggerEvent> trigger;
    try {
      trigger = devices.trigger->next(100ms);
    } catch (const std::exception& e) {
      {
        std::lock_guard lock(health_mutex);
        trigger_error = e.what();
      }
      control.reportError(std::string("trigger source: ") + e.what(), "trigger");
      std::this_thread::sleep_for(100ms);
      continue;
    }
    if (trigger) {
      trigger_seen = steadyNowNs();
      bool had_error = false;
      {
        std::lock_guard lock(health_mutex);
        had_error = !trigger_error.empty();
        trigger_error.clear();
      }
      if (had_error) control.clearError("trigger");
    }
    if (trigger) events.push({control.generation(), TriggerEvent{trigger->stamp_ns}});
  }
}

// Groups frames by trigger time across the running request's schedule
// (pipeline::ScheduleSynchroniser); schedule changes are taken before any
// frame or trigger queued after them.
void ScanEngine::Impl::groupLoop(Heartbeat& hb) {
  pipeline::ScheduleSynchroniser grouping(camera_ids, config.synchroniser);
  std::uint64_t active = 0;  // the generation whose schedule runs
  auto takeSchedule = [&] {
    while (std::optional<ScheduleEvent> e = schedule.tryPop()) applyScheduleEvent(*e, active, grouping);
  };
  while (running) {
    hb.beat();
    takeSchedule();
    std::optional<InputEvent> event = events.pop(50ms);
    takeSchedule();
    if (event && event->generation == active) {  // else from a stopped request
      if (auto* frame = std::get_if<FrameEvent>(&event->payload)) {
        grouping.pushFrame(frame->camera, std::move(frame->frame));
      } else {
        grouping.pushTrigger(std::get<TriggerEvent>(event->payload).stamp_ns);
      }
      for (auto& set : grouping.takeCompleted()) sets.push({active, std::move(set)});
    }
    last_trigger_ns = grouping.lastTriggerNs();
    const pipeline::ScheduleCounters counts = grouping.counters();
    statistics.setTriggerGrouping({counts.frames_unmatched, counts.triggers_incomplete});
  }
}

void ScanEngine::Impl::processLoop(Heartbeat& hb) {
  while (running) {
    hb.beat();
    std::optional<SetItem> item = sets.pop(50ms);
    if (!item || item->generation != control.generation()) continue;
    recorder.record(item->set);  // a no-op unless this request records
    if (settings_pending) applyPendingSettings();
    const std::shared_ptr<const RequestOptions> options = control.options();
    const pipeline::ImageSet& set = *item->set;
    const pipeline::TimestampNs processing_ns = pipeline::systemClockNs();
    SetOutcome outcome =
        processor.process(set, control.camerasFor(set.pattern_name, *options),
                          options->motion_compensation.value_or(motion_enabled.load()));
    if (!outcome.warning.empty()) control.reportError(outcome.warning);
    if (!outcome.ok()) {
      control.reportError(outcome.error);
      continue;
    }
    ResultItem result{item->generation, {}, lastExposureNs(set), processing_ns, pipeline::systemClockNs()};
    for (CameraScan& scan : outcome.scans)
      result.results.push_back({0, set.pattern_name, scan.camera_id, scan.bit_depth,
                                std::move(scan.maps), std::move(scan.cloud),
                                processing_config.cloud_unit_mm * 1e-3, item->set});
    results.push(std::move(result));
  }
}

// Rebuilds the processing stages with the reloaded run-time settings
// (decoder, triangulator, motion compensation); the rest of the reloaded
// config is the running one (a change there needs a restart).
void ScanEngine::Impl::applyPendingSettings() {
  std::optional<DaemonConfig> settings;
  {
    std::lock_guard lock(settings_mutex);
    settings.swap(pending_settings);
    settings_pending = false;
  }
  if (!settings) return;
  ProcessingConfig next = processing_config;
  next.decoder = settings->decoder;
  next.triangulator = settings->triangulator;
  next.motion = settings->motion.options;
  next.motion_enabled = settings->motion.enabled;
  const std::string error = processor.reconfigure(next);
  if (!error.empty()) {
    control.reportError("applying reloaded settings: " + error);
    return;
  }
  motion_enabled = next.motion_enabled;
}

void ScanEngine::Impl::outputLoop(Heartbeat& hb) {
  while (running) {
    hb.beat();
    std::optional<ResultItem> item = results.pop(50ms);
    checkHealth();
    if (!item) {
      control.checkDeadline();
      continue;
    }
    const std::optional<std::uint64_t> index = control.countScan(item->generation);
    if (!index) continue;  // from a stopped request
    statistics.scanPublished(item->generation);
    next_health_check = Clock::time_point{};  // a scan may end a degraded state
    for (ScanResult& r : item->results) {
      r.scan_index = *index;
      try {
        output(r);
      } catch (const std::exception& e) {
        control.reportError(std::string("publishing: ") + e.what());
      }
    }
    statistics.scanStages(stageTimes(item->exposed_ns, item->processing_ns, item->processed_ns,
                                     pipeline::systemClockNs()));
    control.finishIfComplete(item->generation);
  }
}

// Every 100 ms (and after each scan): is the running scan degraded?
void ScanEngine::Impl::checkHealth() {
  const auto now = Clock::now();
  if (now < next_health_check) return;
  next_health_check = now + 100ms;
  control.setDegraded(degradedCause());
}

// Why the running scan is degraded ("" = it is not): with the trigger board,
// a camera without frames or a trigger source without triggers for
// runtime.stall_timeout_s; in either mode, no scan published for that long
// plus a sequence's time (since the start or the last scan).
std::string ScanEngine::Impl::degradedCause() {
  const RequestControl::Health h = control.health();
  if (!h.scanning) return "";
  const double stall_s = config.runtime.stall_timeout_s;
  const std::int64_t since_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(h.since.time_since_epoch()).count();
  const std::int64_t now_ns = steadyNowNs();
  auto silentFor = [&](std::int64_t seen_ns) { return (now_ns - std::max(seen_ns, since_ns)) * 1e-9; };
  std::string cause;
  auto add = [&](const std::string& text) { cause += (cause.empty() ? "" : "; ") + text; };
  if (h.trigger == TriggerMode::kHardware) {
    std::lock_guard lock(health_mutex);
    for (std::size_t i = 0; i < camera_ids.size(); ++i) {
      const double silent = silentFor(camera_seen[i].load());
      if (silent >= stall_s)
        add("camera '" + camera_ids[i] + "': no frame for " + secondsText(silent) + " s" +
            (camera_errors[i].empty() ? "" : " (" + camera_errors[i] + ")"));
    }
    const double silent = silentFor(trigger_seen.load());
    if (silent >= stall_s)
      add("trigger source: no trigger for " + secondsText(silent) + " s" +
          (trigger_error.empty() ? "" : " (" + trigger_error + ")"));
  }
  const std::optional<Clock::time_point> last = statistics.lastScan(control.generation());
  const double no_scan_s = std::chrono::duration<double>(
                               Clock::now() - std::max(last.value_or(h.since), h.since)).count();
  if (no_scan_s >= stall_s + h.sequence_s) {
    const std::uint64_t incomplete = last ? statistics.incompleteSinceLastScan() : 0;
    add("no scan published for " + secondsText(no_scan_s) + " s" +
        (incomplete > 0 ? " (" + std::to_string(incomplete) + " sequences incomplete)" : ""));
  }
  return cause;
}

// Starts delayed requests and carries out pattern switches at their time
// (RequestControl::serviceTimers), and runs software-trigger requests: one
// sequence per iteration, its pattern read at the sequence boundary (a
// switch never mixes patterns within a set), grouped by the
// IndexedSynchroniser.
void ScanEngine::Impl::controlLoop(Heartbeat& hb) {
  bool holding = false;  // the camera threads are parked
  while (running) {
    hb.beat();
    if (control.serviceTimers()) continue;
    const std::optional<RequestControl::SoftwareRun> run = control.softwareRun();
    if (!run) {
      if (holding) {
        software.stop();
        gate.release();
        holding = false;
        continue;
      }
      control.waitForChange(100ms);
      continue;
    }
    const std::uint64_t gen = run->generation;
    if (software.finished(gen, run->scans_requested)) {
      control.waitForChange(100ms);  // all sets taken; the output thread ends the request
      continue;
    }
    if (!holding) {
      if (!gate.hold(3s, [&] { hb.beat(); })) {
        gate.release();
        control.endRequest(gen, "software trigger: the camera threads did not pause");
        continue;
      }
      holding = true;
    }
    SoftwareRuns::Outcome outcome = software.acquire(gen, run->pattern, run->frame_count, run->cameras, [&] {
      hb.beat();
      return !running || control.generation() != gen;
    });
    statistics.framesReceived(outcome.frames);
    if (outcome.set) sets.push({gen, std::move(outcome.set)});
    if (outcome.end_request) {
      control.endRequest(gen, outcome.fault);
    } else if (!outcome.fault.empty()) {
      control.reportError(outcome.fault);
    }
    const pipeline::SynchroniserCounters& counts = software.counters();
    statistics.setSoftwareGrouping({counts.frames_unmatched, counts.triggers_incomplete});
  }
  if (holding) gate.release();
}

ScanEngine::ScanEngine(const DaemonConfig& config, EngineDevices devices, OutputCallback output,
                       ResultContents contents)
    : impl_(std::make_unique<Impl>(config, std::move(devices), std::move(output), contents)) {
  Impl& d = *impl_;
  const std::size_t k = d.devices.cameras.size();
  d.heartbeats = std::vector<Heartbeat>(k + 5);
  for (std::size_t i = 0; i < k; ++i) d.threads.emplace_back([&d, i] { d.cameraLoop(i, d.heartbeats[i]); });
  d.threads.emplace_back([&d, k] { d.triggerLoop(d.heartbeats[k]); });
  d.threads.emplace_back([&d, k] { d.groupLoop(d.heartbeats[k + 1]); });
  d.threads.emplace_back([&d, k] { d.processLoop(d.heartbeats[k + 2]); });
  d.threads.emplace_back([&d, k] { d.outputLoop(d.heartbeats[k + 3]); });
  d.threads.emplace_back([&d, k] { d.controlLoop(d.heartbeats[k + 4]); });
}

ScanEngine::~ScanEngine() {
  Impl& d = *impl_;
  try {
    d.devices.projector->stop();
  } catch (...) {
  }
  d.gate.wakeAll([&d] { d.running = false; });
  d.control.shutDown();
  for (auto& camera : d.devices.cameras) camera->stop();
  d.devices.trigger->stop();
  d.events.close();
  d.schedule.close();
  d.sets.close();
  d.results.close();
  for (auto& t : d.threads) t.join();
}

CommandResult ScanEngine::start(const std::string& pattern, int count, const std::string& recording) {
  StartRequest request;
  request.pattern = pattern;
  request.count = count;
  request.recording = recording;
  return start(request);
}

CommandResult ScanEngine::start(const StartRequest& request) { return impl_->control.start(request); }
CommandResult ScanEngine::stop() { return impl_->control.stop(); }
CommandResult ScanEngine::selectPattern(const std::string& name) {
  return impl_->control.selectPattern(name);
}

std::vector<std::string> ScanEngine::patterns() const {
  std::vector<std::string> names;
  for (const auto& p : impl_->config.patterns) names.push_back(p.name);
  return names;
}

const DaemonConfig& ScanEngine::config() const { return impl_->config; }

void ScanEngine::applyRuntimeSettings(const DaemonConfig& settings) {
  std::lock_guard lock(impl_->settings_mutex);
  impl_->pending_settings = settings;
  impl_->settings_pending = true;
}

void ScanEngine::reportError(const std::string& message, const std::string& source) {
  impl_->control.reportError(message, source);
}
void ScanEngine::clearError(const std::string& source) { impl_->control.clearError(source); }

EngineStatus ScanEngine::status() const {
  Impl& d = *impl_;
  EngineStatus s;
  d.control.fillStatus(s);
  s.scan_rate_hz = s.state == ScanState::kScanning || s.state == ScanState::kDegraded
                       ? d.statistics.scanRateHz(d.control.generation(), d.config.runtime.stall_timeout_s)
                       : 0.0;
  s.frames_overflow = d.events.dropped();
  s.frames_unmatched = d.statistics.framesUnmatched() + d.software.staleFrames();
  s.frames_dropped = s.frames_overflow + s.frames_unmatched;
  s.sets_overflow = d.sets.dropped() + d.results.dropped();
  s.sets_not_recorded = d.recorder.dropped();
  s.sets_dropped = s.sets_overflow + s.sets_not_recorded;
  s.sets_incomplete = d.statistics.setsIncomplete();
  s.sets_recorded = d.recorder.written();
  s.sets_over_quota = d.recorder.overQuota();
  if (!s.recording.empty() && !d.recorder.active()) s.recording.clear();  // stopped by itself
  const Recorder::Error recorder_error = d.recorder.lastError();
  s.errors_reported += recorder_error.count;
  const double hold_ns = d.config.runtime.last_error_hold_s * 1e9;
  const bool aged = hold_ns > 0 && static_cast<double>(pipeline::systemClockNs() - recorder_error.stamp_ns) > hold_ns;
  if (!recorder_error.message.empty() && !aged && recorder_error.stamp_ns >= s.last_error_ns) {
    s.last_error = recorder_error.message;
    s.last_error_ns = recorder_error.stamp_ns;
  }
  s.motion_compensation = d.control.options()->motion_compensation.value_or(d.motion_enabled.load());
  s.frame_rate_hz = d.statistics.frameRateHz();
  const StageSummary stages = d.statistics.stageSummary();
  s.latency_ms = stages.total_median_ms;
  s.latency_max_ms = stages.total_max_ms;
  s.wait_ms = stages.median.wait_ms;
  s.processing_ms = stages.median.processing_ms;
  s.publish_ms = stages.median.publish_ms;
  return s;
}

bool ScanEngine::healthy() const {
  for (const auto& hb : impl_->heartbeats)
    if (!hb.recent(2s)) return false;
  return true;
}

}  // namespace sl::daemon
