// The scan engine's threads and the queues between them; each thread runs
// one stage (engine/*.h, pipeline stages) and owns it.
#include "sl/daemon/scan_engine.h"

#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <latch>
#include <string>
#include <thread>
#include <utility>
#include <variant>

#include "engine/adaptive_scan.h"
#include "engine/control_loop.h"
#include "engine/decode_watch.h"
#include "engine/device_health.h"
#include "engine/memory_prefault.h"
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

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::client::ScanState;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

// The thread's name as ps -L and top -H show it (Linux: up to 15 characters).
void nameThisThread(const std::string& name) {
  pthread_setname_np(pthread_self(), name.substr(0, 15).c_str());
}

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

// Counts an image set from its grouping until its scan was published or the
// set was dropped (a full queue, a stopped request, a processing error):
// carried by SetItem, then by its ResultItem; move-only.
class InFlight {
 public:
  explicit InFlight(std::atomic<int>& count) : count_(&count) { ++count; }
  InFlight(InFlight&& other) noexcept : count_(std::exchange(other.count_, nullptr)) {}
  InFlight& operator=(InFlight&& other) noexcept {
    release();
    count_ = std::exchange(other.count_, nullptr);
    return *this;
  }
  InFlight(const InFlight&) = delete;
  InFlight& operator=(const InFlight&) = delete;
  ~InFlight() { release(); }

 private:
  void release() {
    if (count_) --*count_;
    count_ = nullptr;
  }
  std::atomic<int>* count_;
};

struct SetItem {
  std::uint64_t generation = 0;
  std::shared_ptr<const pipeline::ImageSet> set;
  InFlight in_flight;
};
struct ResultItem {
  std::uint64_t generation = 0;
  std::vector<ScanResult> results;  // one per triangulating camera, same scan
  // System clock: the sequence's last exposure, processing start and end.
  pipeline::TimestampNs exposed_ns = 0, processing_ns = 0, processed_ns = 0;
  InFlight in_flight;
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

// `p` with the per-point quality the results' consumer asks for.
ProcessingConfig withQuality(ProcessingConfig p, const ResultContents& contents) {
  p.depth_sigma = contents.depth_sigma;
  p.normals = contents.normals;
  p.normal_step = contents.normal_step;
  return p;
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
        processing_config(withQuality(processingConfigOf(config, camera_ids,
                                                         contents.cloud_unit == CloudUnit::kMetres ? 1000.0 : 1.0,
                                                         contents.projector_maps),
                                      contents)),
        processor(processing_config),
        motion_enabled(processing_config.motion_enabled),
        software(this->devices.cameras, this->devices.projector, config.software_trigger),
        last_frame_ns(camera_ids.size()),
        device_health(camera_ids),
        control(config, linksOf(config)),
        control_loop(control, software, gate, statistics,
                     [this](std::uint64_t generation, std::shared_ptr<const pipeline::ImageSet> set) {
                       sets.push({generation, std::move(set), InFlight(sets_in_flight)});
                     }) {
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

  // Image sets between grouping and publication (InFlight): a finite
  // request is not ended for lost sets while one is still on its way.
  std::atomic<int> sets_in_flight{0};

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
  PendingSettings pending_settings;           // a config reload -> processing thread

  // Written by the grouping / camera threads, read by request control.
  std::atomic<pipeline::TimestampNs> last_trigger_ns{0};
  std::vector<std::atomic<pipeline::TimestampNs>> last_frame_ns;  // per camera

  // Device and scan health (camera, trigger threads report; output thread checks).
  DeviceHealth device_health;
  DecodeWatch decode_watch;  // processing thread reports; output thread checks
  Clock::time_point next_health_check;  // output thread
  // Adaptive scanning: velocity from the DDS edge, the policy run by the
  // output thread, its compensation and pause read by the processing thread.
  AdaptiveScan adaptive{config.adaptive};

  CameraGate gate{camera_ids.size()};  // parks the camera threads (software trigger)
  RequestControl control;  // after the members its links point at
  ControlLoop control_loop;  // control thread

  std::atomic<bool> running{true};
  // Counted down by the stage threads when their memory is prefaulted; the
  // constructor returns (and the daemon says ready) after that.
  std::latch prefaulted{static_cast<std::ptrdiff_t>(devices.cameras.size()) + 2};
  std::vector<Heartbeat> heartbeats;  // sized before threads start
  std::vector<std::thread> threads;

  void cameraLoop(std::size_t index, Heartbeat& hb);
  void triggerLoop(Heartbeat& hb);
  void groupLoop(Heartbeat& hb);
  void processLoop(Heartbeat& hb);
  void outputLoop(Heartbeat& hb);
  void applySettings(const DaemonConfig& settings);
  void checkHealth();
};

void ScanEngine::Impl::cameraLoop(std::size_t index, Heartbeat& hb) {
  auto& camera = *devices.cameras[index];
  while (running) {
    hb.beat();
    if (gate.parkIfHeld([&] { hb.beat(); }, [&] { return running.load(); })) continue;
    std::optional<pipeline::Frame> frame;
    try {
      frame = camera.grab(100ms);
    } catch (const std::exception& e) {
      device_health.cameraFailed(index, e.what());
      control.reportError("camera '" + camera.id() + "': " + e.what(), "camera:" + camera.id());
      std::this_thread::sleep_for(100ms);
      continue;
    }
    if (frame) {
      if (device_health.cameraDelivered(index, steadyNowNs())) control.clearError("camera:" + camera.id());
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
      device_health.triggerFailed(e.what());
      control.reportError(std::string("trigger source: ") + e.what(), "trigger");
      std::this_thread::sleep_for(100ms);
      continue;
    }
    if (!trigger) continue;
    if (device_health.triggerDelivered(steadyNowNs())) control.clearError("trigger");
    events.push({control.generation(), TriggerEvent{trigger->stamp_ns}});
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
      for (auto& set : grouping.takeCompleted()) sets.push({active, std::move(set), InFlight(sets_in_flight)});
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
    if (std::optional<DaemonConfig> settings = pending_settings.take()) applySettings(*settings);
    const std::shared_ptr<const RequestOptions> options = control.options();
    const pipeline::ImageSet& set = *item->set;
    // Adaptive scanning: a paused mode drops the set (recorded all the
    // same); a mode's compensation overrides the request's.
    if (adaptive.paused(item->generation)) continue;
    const bool compensate = adaptive.compensationFor(item->generation, set.pattern_name)
                                .value_or(options->motion_compensation.value_or(motion_enabled.load()));
    const pipeline::TimestampNs processing_ns = pipeline::systemClockNs();
    SetOutcome outcome = processor.process(set, control.camerasFor(set.pattern_name, *options), compensate);
    if (!outcome.warning.empty()) control.reportError(outcome.warning);
    if (!outcome.ok()) {
      control.reportError(outcome.error);
      continue;
    }
    ResultItem result{item->generation, {}, lastExposureNs(set), processing_ns, pipeline::systemClockNs(),
                      std::move(item->in_flight)};
    // Decode health: an implausible cloud is wrong everywhere (the pattern
    // file does not describe the frames); it is counted and, unless
    // runtime.publish_implausible, not published, and a finite request ends
    // with the cause (DecodeWatch keeps a continuous one degraded).
    std::string implausible;
    for (std::size_t i = 0; i < outcome.scans.size(); ++i) {
      CameraScan& scan = outcome.scans[i];
      const DecodeWatch::Verdict verdict =
          decode_watch.report(set.pattern_name, scan.camera_id, scan.health, i == 0);
      if (verdict.implausible) {
        if (implausible.empty()) implausible = verdict.cause;
        if (!config.runtime.publish_implausible) continue;
      }
      result.results.push_back({0, set.pattern_name, scan.camera_id, scan.bit_depth,
                                std::move(scan.maps), std::move(scan.cloud),
                                processing_config.cloud_unit_mm * 1e-3, item->set,
                                std::move(scan.quality)});
    }
    decode_watch.setDone(item->generation, implausible);
    if (!implausible.empty() && !config.runtime.publish_implausible &&
        control.health().scans_requested > 0) {
      control.endRequest(item->generation, implausible + "; cloud not published (runtime.publish_implausible)");
      continue;
    }
    if (result.results.empty()) continue;
    results.push(std::move(result));
  }
}

// The reloaded run-time settings (decoder, triangulator, motion
// compensation); the rest of the reloaded config is the running one (a
// change there needs a restart).
void ScanEngine::Impl::applySettings(const DaemonConfig& settings) {
  const std::string error = processor.applyRuntimeSettings(settings);
  if (!error.empty()) return control.reportError("applying reloaded settings: " + error);
  motion_enabled = processor.motionEnabled();
}

void ScanEngine::Impl::outputLoop(Heartbeat& hb) {
  while (running) {
    hb.beat();
    std::optional<ResultItem> item = results.pop(50ms);
    checkHealth();
    if (!item) {
      control.checkDeadline(sets_in_flight.load() > 0);
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

// Every 100 ms (and after each scan): the adaptive policy, and is the
// running scan degraded?
void ScanEngine::Impl::checkHealth() {
  const auto now = Clock::now();
  if (now < next_health_check) return;
  next_health_check = now + 100ms;
  adaptive.update(control, steadyNowNs());
  const std::uint64_t generation = control.generation();
  // Paused by adaptive scanning: no scan is published on purpose; that is
  // the cause, not a stall.
  if (const std::string paused = adaptive.pauseCause(generation); !paused.empty())
    return control.setDegraded(paused);
  RequestControl::Health health = control.health();
  if (const std::int64_t resumed_ns = adaptive.resumedNs(generation); resumed_ns > 0)
    health.since = std::max(health.since, Clock::time_point(std::chrono::nanoseconds(resumed_ns)));
  std::string cause = degradedCause(health, device_health, statistics, generation,
                                    config.runtime.stall_timeout_s);
  // A decode that stays implausible comes first: the scans it withholds are
  // what "no scan published" would report next.
  if (const std::string decode = decode_watch.degradedCause(generation); !decode.empty())
    cause = cause.empty() ? decode : decode + "; " + cause;
  control.setDegraded(cause);
}

ScanEngine::ScanEngine(const DaemonConfig& config, EngineDevices devices, OutputCallback output,
                       ResultContents contents)
    : impl_(std::make_unique<Impl>(config, std::move(devices), std::move(output), contents)) {
  Impl& d = *impl_;
  const std::size_t k = d.devices.cameras.size();
  d.heartbeats = std::vector<Heartbeat>(k + 5);
  // Named for ps -L / top -H (at most 15 characters). The stages that
  // allocate images and clouds first touch the memory they will recycle
  // (engine/memory_prefault.h).
  const PrefaultPlan plan = prefaultPlanOf(d.config, kInputQueueCapacity, contents.keeps_clouds);
  for (std::size_t i = 0; i < k; ++i)
    d.threads.emplace_back([&d, i, plan] {
      nameThisThread("sl-camera" + std::to_string(i));
      prefaultThreadHeap(plan.frame_bytes, plan.frames);
      d.prefaulted.count_down();
      d.cameraLoop(i, d.heartbeats[i]);
    });
  d.threads.emplace_back([&d, k] {
    nameThisThread("sl-trigger");
    d.triggerLoop(d.heartbeats[k]);
  });
  d.threads.emplace_back([&d, k] {
    nameThisThread("sl-group");
    d.groupLoop(d.heartbeats[k + 1]);
  });
  d.threads.emplace_back([&d, k, plan] {
    nameThisThread("sl-process");
    prefaultThreadHeap(plan.cloud_bytes, plan.process_clouds);
    d.prefaulted.count_down();
    d.processLoop(d.heartbeats[k + 2]);
  });
  d.threads.emplace_back([&d, k, plan] {
    nameThisThread("sl-output");
    prefaultThreadHeap(plan.output_block_bytes, plan.output_blocks);
    d.prefaulted.count_down();
    d.outputLoop(d.heartbeats[k + 3]);
  });
  d.threads.emplace_back([&d, k] {
    nameThisThread("sl-control");
    d.control_loop.run(d.running, d.heartbeats[k + 4]);
  });
  d.prefaulted.wait();
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

void ScanEngine::applyRuntimeSettings(const DaemonConfig& settings) { impl_->pending_settings.post(settings); }

void ScanEngine::reportError(const std::string& message, const std::string& source) {
  impl_->control.reportError(message, source);
}
void ScanEngine::clearError(const std::string& source) { impl_->control.clearError(source); }

void ScanEngine::setVelocity(const VelocitySample& velocity) { impl_->adaptive.setVelocity(velocity); }

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
  s.sets_dropped = s.sets_overflow;  // + sets_not_recorded below
  addRecorderStatus(s, d.recorder, d.config.runtime.last_error_hold_s, pipeline::systemClockNs());
  s.motion_compensation = d.adaptive.compensation(d.control.generation())
                              .value_or(d.control.options()->motion_compensation.value_or(d.motion_enabled.load()));
  d.adaptive.fill(s);
  d.statistics.fillStatus(s);
  d.decode_watch.fill(s);
  return s;
}

bool ScanEngine::healthy() const {
  for (const auto& hb : impl_->heartbeats)
    if (!hb.recent(2s)) return false;
  return true;
}

}  // namespace sl::daemon
