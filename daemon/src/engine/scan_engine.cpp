#include "sl/daemon/scan_engine.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <optional>
#include <limits>
#include <map>
#include <set>
#include <utility>
#include <variant>

#include "intensity_transfer.h"
#include "recorder.h"
#include "software_trigger.h"
#include "sl/daemon/bounded_queue.h"
#include "sl/pipeline/codec.h"
#include "sl/pipeline/motion_compensation.h"
#include "sl/pipeline/scan_processor.h"
#include "sl/pipeline/synchroniser.h"
#include "sl/pipeline/triangulator.h"

namespace sl::daemon {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

const char* toString(ScanState s) {
  switch (s) {
    case ScanState::kIdle: return "idle";
    case ScanState::kScanning: return "scanning";
    case ScanState::kError: return "error";
    case ScanState::kWaiting: return "waiting";
  }
  return "?";
}

namespace {

// Options of the current request that the processing thread applies per set.
struct RequestOptions {
  std::string cameras_pattern;       // the pattern `cameras` was given for
  std::vector<std::string> cameras;  // empty: the pattern's configured cameras
  std::optional<bool> motion_compensation;  // empty: as configured
};

// Events for the sync thread. Each carries the request generation it belongs
// to; events of an older generation are discarded.
struct FrameEvent {
  std::size_t camera = 0;
  pipeline::Frame frame;
};
struct TriggerEvent {
  pipeline::TimestampNs stamp_ns = 0;
};
struct PatternEvent {  // a new schedule: reset the synchroniser
  std::string name;
  int frame_count = 0;
  // Frames and triggers stamped before this belong to an earlier schedule
  // (possibly another pattern) and are never grouped into this one's sets.
  pipeline::TimestampNs not_before_ns = 0;
  // A pattern switch within a continuous request: frames and triggers
  // stamped before this sequence boundary still complete the previous
  // pattern's last sequence (0 = a new request: nothing carries over).
  pipeline::TimestampNs previous_until_ns = 0;
};
// A pattern switch is pending at this sequence boundary: until its
// PatternEvent, what is stamped at or after it belongs to no set (the
// projector may still start the old pattern's next sequence).
struct BoundaryEvent {
  pipeline::TimestampNs at_ns = 0;
};
// The request ended: what the synchroniser still holds is a sequence the
// stop cut short (not a fault, dropped silently) or, when the request ended
// with an error, one whose frames were lost (counted as incomplete).
struct EndEvent {
  bool count_pending = false;
};
struct Event {
  std::uint64_t generation = 0;
  std::variant<FrameEvent, TriggerEvent, PatternEvent, BoundaryEvent, EndEvent> payload;
};

struct SetItem {
  std::uint64_t generation = 0;
  std::shared_ptr<const pipeline::ImageSet> set;
};

struct ResultItem {
  std::uint64_t generation = 0;
  std::vector<ScanResult> results;  // one per triangulating camera, same scan
};

// Queue sizes between stages. Frames: enough for a few sequences of the
// longest pattern; sets and results: the configured depth.
constexpr std::size_t kEventQueueCapacity = 64;

class Heartbeat {
 public:
  void beat() { last_ = Clock::now().time_since_epoch().count(); }
  bool recent(std::chrono::nanoseconds max_age) const {
    return Clock::now().time_since_epoch().count() - last_.load() < max_age.count();
  }

 private:
  std::atomic<Clock::rep> last_{Clock::now().time_since_epoch().count()};
};

}  // namespace

struct ScanEngine::Impl {
  Impl(const DaemonConfig& config, EngineDevices devices, OutputCallback output)
      : config(config),
        devices(std::move(devices)),
        output(std::move(output)),
        events(kEventQueueCapacity),
        sets(config.runtime.queue_depth),
        results(config.runtime.queue_depth),
        motion(config.motion.options),
        motion_enabled(config.motion.enabled),
        software(this->devices.cameras, this->devices.projector, config.software_trigger),
        active_trigger(config.runtime.trigger) {
    for (const auto& p : config.patterns)
      decoders.emplace(p.name, pipeline::Decoder(p, config.decoder));
    buildTriangulators(config);
    // Which cameras triangulate which pattern; every one must exist and be calibrated.
    for (const auto& p : config.patterns) {
      const auto listed = config.pattern_cameras.find(p.name);
      const std::vector<std::string> ids =
          listed != config.pattern_cameras.end()
              ? listed->second
              : std::vector<std::string>{this->devices.cameras.front()->id()};
      for (const auto& id : ids) {
        if (!triangulators.count(id))
          throw std::runtime_error(config.source_path + ": pattern '" + p.name + "' names camera '" +
                                   id + "', which the sensor lacks or which has no calibration "
                                   "(calibration: for the first camera, calibrations: for others)");
      }
      pattern_cameras[p.name] = ids;
    }
    // Calibrations by camera id (for intensity cameras): the first camera's
    // and those of `calibrations:`.
    calibrations[this->devices.cameras.front()->id()] = config.calibration;
    for (const auto& [id, calibration] : config.extra_calibrations) calibrations[id] = calibration;
    for (const auto& [pattern, id] : config.pattern_intensity_camera) {
      const bool exists = std::any_of(this->devices.cameras.begin(), this->devices.cameras.end(),
                                      [&](const auto& c) { return c->id() == id; });
      if (!exists || !calibrations.count(id))
        throw std::runtime_error(config.source_path + ": pattern '" + pattern +
                                 "' takes its intensity from camera '" + id +
                                 "', which the sensor lacks or which has no calibration");
    }
    if (config.runtime.trigger == TriggerMode::kSoftware) {
      const std::string why = software.unsupportedReason();
      if (!why.empty())
        throw std::runtime_error(config.source_path + ": runtime.trigger is software, but " + why);
    }
    current_pattern = config.runtime.default_pattern;
    this->devices.projector->select(current_pattern);
    for (auto& camera : this->devices.cameras) camera->start();
  }

  // --- configuration and devices (immutable after construction) ---
  const DaemonConfig config;
  EngineDevices devices;
  OutputCallback output;

  // --- queues between the threads ---
  BoundedQueue<Event> events;
  BoundedQueue<SetItem> sets;
  BoundedQueue<ResultItem> results;

  // Writes image sets of requests that ask for a recording (own thread).
  Recorder recorder;
  std::string recording_name;  // guarded by mutex

  // --- stages, each used by one thread only ---
  std::map<std::string, pipeline::Decoder> decoders;               // processing thread
  // Per camera id (processing thread); built from the calibrations.
  std::map<std::string, pipeline::Triangulator> triangulators;
  // Decode + triangulate split over row blocks on the processing thread's own
  // workers, reusing buffers that consumers have released (processing thread).
  pipeline::ScanProcessor processor;
  std::map<std::string, std::vector<std::string>> pattern_cameras;  // immutable after construction
  std::map<std::string, pipeline::CameraProjectorCalibration> calibrations;  // immutable, by camera id
  void buildTriangulators(const DaemonConfig& settings);
  // A copy of `cloud` (triangulated by `camera_id`) with the intensity seen
  // by the pattern's intensity camera; nullptr when the pattern has none.
  std::shared_ptr<const pipeline::PointCloud> colouredCopy(const pipeline::ImageSet& set,
                                                           const std::string& camera_id,
                                                           const pipeline::PointCloud& cloud) const {
    const auto other = config.pattern_intensity_camera.find(set.pattern_name);
    if (other == config.pattern_intensity_camera.end() || other->second == camera_id) return nullptr;
    const auto images = std::find_if(set.cameras.begin(), set.cameras.end(),
                                     [&](const auto& c) { return c.camera_id == other->second; });
    if (images == set.cameras.end())
      throw std::runtime_error("no images of intensity camera '" + other->second + "' in the set");
    auto coloured = std::make_shared<pipeline::PointCloud>(cloud);
    transferIntensity(*coloured, calibrations.at(camera_id), calibrations.at(other->second), *images);
    return coloured;
  }
  // dds.frame_id for the first camera, "<id>_optical_frame" for the others.
  std::string frameIdOf(const std::string& camera_id) const {
    return camera_id == devices.cameras.front()->id() ? config.dds.frame_id
                                                      : camera_id + "_optical_frame";
  }
  pipeline::MotionCompensator motion;                              // processing thread
  // As configured (or reloaded); written by the processing thread.
  std::atomic<bool> motion_enabled{false};
  // Software-trigger acquisition (control thread only).
  SoftwareTrigger software;
  // Settings from a config reload, applied by the processing thread before
  // its next image set (guarded by mutex; the flag avoids taking it per set).
  std::optional<DaemonConfig> pending_settings;
  std::atomic<bool> settings_pending{false};
  void applyPendingSettings();

  // --- control state ---
  mutable std::mutex mutex;
  std::string current_pattern;            // guarded by mutex
  ScanState state = ScanState::kIdle;     // guarded by mutex
  std::uint64_t scans_requested = 0;      // guarded by mutex
  std::uint64_t scans_done = 0;           // guarded by mutex
  std::uint64_t status_version = 0;       // guarded by mutex
  std::string last_error;                 // guarded by mutex
  double scan_rate_hz = 0;                // guarded by mutex
  std::deque<Clock::time_point> recent_scans;  // guarded by mutex
  // The current (or last) request's options; guarded by mutex.
  TriggerMode active_trigger;
  std::shared_ptr<const RequestOptions> request_options = std::make_shared<RequestOptions>();
  // kWaiting: the request to begin at launch_at_ns (system clock); guarded by mutex.
  pipeline::TimestampNs launch_at_ns = 0;
  int pending_count = 0;
  // A pattern switch of a continuous hardware-triggered scan, carried out
  // by the control thread at switch_at_ns, the end of the sequence in
  // progress ("" = none); guarded by mutex.
  std::string switch_pattern;
  pipeline::TimestampNs switch_at_ns = 0;
  // After the projector stopped at the boundary: the new schedule starts once
  // every camera delivered the old pattern's last frame (a restart may
  // discard frames not yet read out), or at drain_until at the latest.
  bool switch_draining = false;
  Clock::time_point drain_until;
  // Per camera: the stamp of the latest frame its thread received.
  std::unique_ptr<std::atomic<pipeline::TimestampNs>[]> last_frame_ns;
  // Wakes the control thread (delayed starts, software-trigger runs); with mutex.
  std::condition_variable control_cv;
  // Camera frames received (all cameras), and the rate derived from them in
  // status(); guarded by mutex.
  std::atomic<std::uint64_t> frames_received{0};
  mutable Clock::time_point rate_window_start = Clock::now();
  mutable std::uint64_t rate_window_frames = 0;
  mutable double frame_rate_hz = 0;
  // Camera threads park while the control thread grabs (software trigger).
  std::mutex gate_mutex;
  std::condition_variable gate_cv;
  bool cameras_held = false;       // guarded by gate_mutex
  std::size_t cameras_parked = 0;  // guarded by gate_mutex
  // A finite request that has not delivered every scan by then ends with an
  // error (frames were lost); guarded by mutex.
  Clock::time_point request_deadline = Clock::time_point::max();
  double sequence_s = 0;  // expected time per sequence of the request; guarded by mutex
  // The generation of the current request; bumped by start() and stop().
  std::atomic<std::uint64_t> generation{0};
  // Set by the sync thread: when the last trigger of a finite request arrived.
  std::atomic<std::uint64_t> triggers_seen{0};
  std::atomic<std::uint64_t> frames_unmatched{0};
  // Pattern and boundary events for the sync thread (never dropped, unlike
  // the frame queue).
  std::mutex control_mutex;
  std::deque<Event> control_events;  // guarded by control_mutex
  void pushControl(Event event) {
    std::lock_guard lock(control_mutex);
    control_events.push_back(std::move(event));
  }
  // Stamp of the latest trigger grouped for the running schedule (0: none
  // yet); set by the sync thread, reset with each PatternEvent.
  std::atomic<pipeline::TimestampNs> last_trigger_ns{0};
  std::atomic<std::uint64_t> sets_incomplete{0};

  std::atomic<bool> running{true};
  std::vector<Heartbeat> heartbeats;  // sized before threads start
  std::vector<std::thread> threads;

  void cameraLoop(std::size_t index, Heartbeat& hb);
  void triggerLoop(Heartbeat& hb);
  void syncLoop(Heartbeat& hb);
  void processLoop(Heartbeat& hb);
  void outputLoop(Heartbeat& hb);
  void controlLoop(Heartbeat& hb);
  bool holdCameras(Heartbeat& hb);
  void releaseCameras();
  void finishRequestLocked(const std::string& error);
  void launchLocked(const std::string& name, int frame_count, int count);
  void beginLocked();
  void switchLocked();
  void recordError(const std::string& error);
  std::vector<std::string> camerasFor(const std::string& pattern,
                                      const RequestOptions& options) const {
    if (!options.cameras.empty() && options.cameras_pattern == pattern) return options.cameras;
    return pattern_cameras.at(pattern);
  }
};

void ScanEngine::Impl::cameraLoop(std::size_t index, Heartbeat& hb) {
  auto& camera = *devices.cameras[index];
  while (running) {
    hb.beat();
    {
      std::unique_lock gate(gate_mutex);
      if (cameras_held) {  // the control thread grabs (software trigger)
        ++cameras_parked;
        gate_cv.notify_all();
        while (cameras_held && running) {
          gate_cv.wait_for(gate, 100ms);
          hb.beat();
        }
        --cameras_parked;
        continue;
      }
    }
    std::optional<pipeline::Frame> frame;
    try {
      frame = camera.grab(100ms);
    } catch (const std::exception& e) {
      recordError("camera '" + camera.id() + "': " + e.what());
      std::this_thread::sleep_for(100ms);
      continue;
    }
    if (frame) {
      ++frames_received;
      last_frame_ns[index] = frame->stamp_ns;
      events.push({generation.load(), FrameEvent{index, std::move(*frame)}});
    }
  }
}

// Parks every camera thread (each finishes the grab in progress); false when
// they did not park within 3 s.
bool ScanEngine::Impl::holdCameras(Heartbeat& hb) {
  std::unique_lock gate(gate_mutex);
  cameras_held = true;
  const auto deadline = Clock::now() + 3s;
  while (cameras_parked < devices.cameras.size() && Clock::now() < deadline) {
    gate_cv.wait_for(gate, 100ms);
    hb.beat();
  }
  return cameras_parked == devices.cameras.size();
}

void ScanEngine::Impl::releaseCameras() {
  {
    std::lock_guard gate(gate_mutex);
    cameras_held = false;
  }
  gate_cv.notify_all();
}

// Starts delayed requests at their time, and runs software-trigger requests:
// one image set per iteration, its pattern read at the sequence boundary (a
// switch never mixes patterns within a set).
void ScanEngine::Impl::controlLoop(Heartbeat& hb) {
  bool holding = false;
  std::uint64_t run_generation = 0;  // generation of the software run in progress
  std::uint64_t acquired = 0;        // its image sets so far
  int failures = 0;                  // consecutive failed sequences
  while (running) {
    hb.beat();
    std::unique_lock lock(mutex);
    if (state == ScanState::kWaiting) {
      const pipeline::TimestampNs now = pipeline::systemClockNs();
      if (now >= launch_at_ns) {
        beginLocked();
      } else {
        control_cv.wait_for(lock, std::min<std::chrono::nanoseconds>(
                                      100ms, std::chrono::nanoseconds(launch_at_ns - now)));
      }
      continue;
    }
    if (state == ScanState::kScanning && !switch_pattern.empty()) {
      const pipeline::TimestampNs now = pipeline::systemClockNs();
      if (switch_draining) {
        bool drained = true;
        // The old pattern's last frame is exposed one image interval before
        // the boundary (half an interval of slack for stamp jitter).
        const pipeline::TimestampNs last_frame =
            switch_at_ns - 3 * config.synchroniser.image_interval_ns / 2;
        for (std::size_t i = 0; i < devices.cameras.size(); ++i)
          drained = drained && last_frame_ns[i].load() >= last_frame;
        if (drained || Clock::now() >= drain_until) {
          switchLocked();
        } else {
          control_cv.wait_for(lock, 2ms);
        }
      } else if (now >= switch_at_ns) {
        try {
          devices.projector->stop();
        } catch (const std::exception& e) {
          switch_pattern.clear();
          finishRequestLocked(std::string("projector: ") + e.what());
          continue;
        }
        switch_draining = true;
        drain_until = Clock::now() + 300ms;
      } else {
        control_cv.wait_for(lock, std::min<std::chrono::nanoseconds>(
                                      100ms, std::chrono::nanoseconds(switch_at_ns - now)));
      }
      continue;
    }
    const bool software_run = state == ScanState::kScanning && active_trigger == TriggerMode::kSoftware;
    if (!software_run) {
      if (holding) {
        lock.unlock();
        software.stop();
        releaseCameras();
        holding = false;
        continue;
      }
      control_cv.wait_for(lock, 100ms);
      continue;
    }
    const std::uint64_t gen = generation.load();
    if (scans_requested != 0 && gen == run_generation && acquired >= scans_requested) {
      control_cv.wait_for(lock, 100ms);  // all sets taken; the output thread ends the request
      continue;
    }
    const std::string pattern = current_pattern;
    const int frame_count = config.findPattern(pattern)->frameCount();
    lock.unlock();
    if (gen != run_generation) {
      software.stop();  // a new request: select its pattern afresh
      run_generation = gen;
      acquired = 0;
      failures = 0;
    }
    if (!holding) {
      if (!holdCameras(hb)) {
        releaseCameras();
        std::lock_guard relock(mutex);
        if (generation.load() == gen)
          finishRequestLocked("software trigger: the camera threads did not pause");
        continue;
      }
      holding = true;
    }
    try {
      auto set = software.acquire(pattern, frame_count, [&] {
        hb.beat();
        return !running || generation.load() != gen;
      });
      if (!set) continue;
      ++acquired;
      failures = 0;
      frames_received += set->cameras.size() * static_cast<std::uint64_t>(frame_count);
      sets.push({gen, std::move(set)});
    } catch (const std::exception& e) {
      std::lock_guard relock(mutex);
      if (generation.load() != gen) continue;  // stopped meanwhile: not a fault
      ++sets_incomplete;
      if (++failures >= 3) {
        finishRequestLocked(std::string(e.what()) + " (3 sequences in a row failed; request ended)");
      } else {
        last_error = e.what();
        ++status_version;
      }
    }
  }
  if (holding) releaseCameras();
}

void ScanEngine::Impl::triggerLoop(Heartbeat& hb) {
  while (running) {
    hb.beat();
    std::optional<drivers::TriggerEvent> trigger;
    try {
      trigger = devices.trigger->next(100ms);
    } catch (const std::exception& e) {
      recordError(std::string("trigger source: ") + e.what());
      std::this_thread::sleep_for(100ms);
      continue;
    }
    if (trigger) events.push({generation.load(), TriggerEvent{trigger->stamp_ns}});
  }
}

void ScanEngine::Impl::syncLoop(Heartbeat& hb) {
  std::vector<std::string> camera_ids;
  for (const auto& c : devices.cameras) camera_ids.push_back(c->id());
  // One synchroniser per schedule; after a pattern switch the previous one
  // keeps what is stamped before the switch's sequence boundary, so the
  // sequence in progress at the switch still completes (with its pattern).
  struct Stage {
    pipeline::Synchroniser synchroniser;
    pipeline::SynchroniserCounters reported{};
  };
  auto fresh = [&] { return Stage{pipeline::Synchroniser(camera_ids, config.synchroniser), {}}; };
  Stage current = fresh();
  std::optional<Stage> previous;
  pipeline::TimestampNs previous_until_ns = 0;
  std::uint64_t active_generation = 0;
  pipeline::TimestampNs not_before_ns = 0;
  pipeline::TimestampNs hold_from_ns = std::numeric_limits<pipeline::TimestampNs>::max();
  auto collect = [&](Stage& stage) {
    for (auto& set : stage.synchroniser.takeCompleted()) sets.push({active_generation, std::move(set)});
    const auto& counters = stage.synchroniser.counters();
    frames_unmatched += counters.frames_unmatched - stage.reported.frames_unmatched;
    sets_incomplete += counters.triggers_incomplete - stage.reported.triggers_incomplete;
    stage.reported = counters;
  };
  // Counts what a synchroniser still holds (setPattern drops and counts it).
  auto retire = [&](std::optional<Stage>& stage) {
    if (!stage) return;
    stage->synchroniser.setPattern("retired", 1);
    collect(*stage);
    stage.reset();
  };
  // Schedule changes come on their own channel (never dropped), taken before
  // any frame or trigger queued after them.
  auto takeControl = [&] {
    for (;;) {
      Event control;
      {
        std::lock_guard lock(control_mutex);
        if (control_events.empty()) return;
        control = std::move(control_events.front());
        control_events.pop_front();
      }
      if (auto* pattern = std::get_if<PatternEvent>(&control.payload)) {
        retire(previous);
        if (pattern->previous_until_ns != 0 && control.generation == active_generation) {
          previous.emplace(std::move(current));
          current = fresh();
          previous_until_ns = pattern->previous_until_ns;
        }
        active_generation = control.generation;
        not_before_ns = pattern->not_before_ns;
        hold_from_ns = std::numeric_limits<pipeline::TimestampNs>::max();
        last_trigger_ns = 0;
        current.synchroniser.setPattern(pattern->name, pattern->frame_count);
      } else if (auto* boundary = std::get_if<BoundaryEvent>(&control.payload)) {
        if (control.generation == active_generation) hold_from_ns = boundary->at_ns;
      } else if (auto* end = std::get_if<EndEvent>(&control.payload)) {
        if (control.generation != active_generation) continue;
        if (end->count_pending) {
          retire(previous);
          current.synchroniser.setPattern("retired", 1);
          collect(current);
        }
        previous.reset();
        current = fresh();
      }
    }
  };
  while (running) {
    hb.beat();
    takeControl();
    std::optional<Event> event = events.pop(50ms);
    takeControl();
    if (!event) continue;
    if (event->generation != active_generation) continue;  // from a stopped request
    const pipeline::TimestampNs stamp =
        std::holds_alternative<FrameEvent>(event->payload)
            ? std::get<FrameEvent>(event->payload).frame.stamp_ns
            : std::get<TriggerEvent>(event->payload).stamp_ns;
    Stage* stage = previous && stamp < previous_until_ns         ? &*previous
                   : stamp >= not_before_ns && stamp < hold_from_ns ? &current
                                                                    : nullptr;
    if (!stage) continue;  // between the switch's boundary and the new schedule
    if (previous && stage == &current &&
        stamp > previous_until_ns + config.synchroniser.max_age_ns) {
      retire(previous);  // its last sequence is long complete or lost
    }
    if (auto* frame = std::get_if<FrameEvent>(&event->payload)) {
      stage->synchroniser.pushFrame(frame->camera, std::move(frame->frame));
    } else {
      stage->synchroniser.pushTrigger(stamp);
      if (stage == &current) last_trigger_ns = stamp;
    }
    collect(*stage);
  }
}

void ScanEngine::Impl::processLoop(Heartbeat& hb) {
  while (running) {
    hb.beat();
    std::optional<SetItem> item = sets.pop(50ms);
    if (!item || item->generation != generation.load()) continue;
    recorder.record(item->set);  // a no-op unless this request records
    // Motion compensation aligns every frame with the reference frame of its
    // sequence; the cloud is then stamped with the reference frame's time.
    if (settings_pending) applyPendingSettings();
    std::shared_ptr<const RequestOptions> options;
    {
      std::lock_guard lock(mutex);
      options = request_options;
    }
    if (options->motion_compensation.value_or(motion_enabled.load())) {
      try {
        pipeline::MotionEstimate estimate;
        item->set = motion.compensate(*item->set, &estimate);
        if (!estimate.all_within_limit)
          recordError("motion compensation: a shift beyond max_shift_px was ignored");
      } catch (const std::exception& e) {
        recordError(std::string("motion compensation: ") + e.what());
        continue;
      }
    }
    const pipeline::ImageSet& set = *item->set;
    try {
      const auto decoder = decoders.find(set.pattern_name);
      if (decoder == decoders.end())
        throw std::runtime_error("no decoder for pattern '" + set.pattern_name + "'");
      ResultItem result{item->generation, {}};
      for (const std::string& camera_id : camerasFor(set.pattern_name, *options)) {
        const auto images = std::find_if(set.cameras.begin(), set.cameras.end(),
                                          [&](const auto& c) { return c.camera_id == camera_id; });
        if (images == set.cameras.end())
          throw std::runtime_error("no images of camera '" + camera_id + "' in the set");
        auto [maps, cloud] = processor.process(decoder->second.codec(), triangulators.at(camera_id),
                                               *images, set.trigger_stamp_ns, frameIdOf(camera_id),
                                               config.dds.publish_projector_maps
                                                   ? pipeline::ScanProcessor::Keep::kMapsAndCloud
                                                   : pipeline::ScanProcessor::Keep::kCloud);
        if (auto coloured = colouredCopy(set, camera_id, *cloud)) cloud = std::move(coloured);
        ScanResult r;
        r.pattern = set.pattern_name;
        r.camera_id = camera_id;
        r.images = item->set;
        r.maps = std::move(maps);
        r.cloud = std::move(cloud);
        result.results.push_back(std::move(r));
      }
      results.push(std::move(result));
    } catch (const std::exception& e) {
      recordError("processing sequence " + std::to_string(set.sequence_id) + ": " + e.what());
    }
  }
}

// One triangulator per camera that has a calibration: the first camera uses
// `calibration`, the others `extra_calibrations` (by id).
void ScanEngine::Impl::buildTriangulators(const DaemonConfig& settings) {
  std::map<std::string, pipeline::Triangulator> built;
  for (std::size_t i = 0; i < devices.cameras.size(); ++i) {
    const std::string id = devices.cameras[i]->id();
    if (i == 0) {
      built.emplace(id, pipeline::Triangulator(settings.calibration, settings.triangulator));
    } else if (const auto c = settings.extra_calibrations.find(id);
               c != settings.extra_calibrations.end()) {
      built.emplace(id, pipeline::Triangulator(c->second, settings.triangulator));
    }
  }
  triangulators.swap(built);
}

// Rebuilds the processing stages from reloaded run-time settings (decoder
// thresholds, triangulator options, motion compensation). Processing thread.
void ScanEngine::Impl::applyPendingSettings() {
  std::optional<DaemonConfig> settings;
  {
    std::lock_guard lock(mutex);
    settings.swap(pending_settings);
    settings_pending = false;
  }
  if (!settings) return;
  try {
    std::map<std::string, pipeline::Decoder> rebuilt;
    for (const auto& p : settings->patterns) rebuilt.emplace(p.name, pipeline::Decoder(p, settings->decoder));
    buildTriangulators(*settings);
    decoders.swap(rebuilt);
    motion = pipeline::MotionCompensator(settings->motion.options);
    motion_enabled = settings->motion.enabled;
  } catch (const std::exception& e) {
    recordError(std::string("applying reloaded settings: ") + e.what());
  }
}

void ScanEngine::Impl::outputLoop(Heartbeat& hb) {
  while (running) {
    hb.beat();
    std::optional<ResultItem> item = results.pop(50ms);
    if (!item) {
      std::lock_guard lock(mutex);
      if (state == ScanState::kScanning && Clock::now() > request_deadline)
        finishRequestLocked("request ended with " + std::to_string(scans_done) + " of " +
                            std::to_string(scans_requested) +
                            " scans: image sets were lost (see the drop counters)");
      continue;
    }
    {
      std::lock_guard lock(mutex);
      if (item->generation != generation.load() || state != ScanState::kScanning) continue;
      ++scans_done;
      for (auto& r : item->results) r.scan_index = scans_done;
      // Software-triggered sets come as fast as the devices allow: the
      // deadline follows progress (as long as a scan arrives every
      // sequence_s + 2 s, nothing is lost).
      if (active_trigger == TriggerMode::kSoftware && scans_requested > scans_done)
        request_deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                              std::chrono::duration<double>(
                                                  (scans_requested - scans_done) * sequence_s + 2.0));
      // Rate over the last (up to) 10 scans: stable, and quick to follow a switch.
      recent_scans.push_back(Clock::now());
      if (recent_scans.size() > 10) recent_scans.pop_front();
      if (recent_scans.size() >= 2)
        scan_rate_hz = (recent_scans.size() - 1) /
                       std::chrono::duration<double>(recent_scans.back() - recent_scans.front())
                           .count();
      ++status_version;
    }
    for (const ScanResult& r : item->results) {
      try {
        output(r);
      } catch (const std::exception& e) {
        recordError(std::string("publishing: ") + e.what());
      }
    }
    std::lock_guard lock(mutex);
    if (item->generation == generation.load() && scans_requested != 0 &&
        scans_done >= scans_requested) {
      finishRequestLocked("");
    }
  }
}

// Starts a new projector schedule of `count` sequences (0 = until stop) of
// pattern `name` as a new generation; caller holds the mutex. Throws what the
// projector throws.
void ScanEngine::Impl::launchLocked(const std::string& name, int frame_count, int count) {
  const std::uint64_t next = generation.load() + 1;
  devices.projector->select(name);
  current_pattern = name;
  const auto now = pipeline::systemClockNs();
  pushControl({next, PatternEvent{name, frame_count, now}});
  generation = next;
  devices.projector->start(count);
}

// Begins the accepted request (state kWaiting until now) with
// current_pattern and pending_count; caller holds the mutex. A device error
// ends it in kError.
void ScanEngine::Impl::beginLocked() {
  const pipeline::PatternSpec* pattern = config.findPattern(current_pattern);
  const int count = pending_count;
  scans_done = 0;
  scan_rate_hz = 0;
  recent_scans.clear();
  // Time per sequence: one image interval per pattern with a trigger board;
  // in software, settle plus (at least) an exposure per pattern, doubled
  // for transfer and processing.
  sequence_s = pattern->frameCount() * config.synchroniser.image_interval_ns * 1e-9;
  if (active_trigger == TriggerMode::kSoftware)
    sequence_s = 2 * pattern->frameCount() *
                 (config.software_trigger.settle_s + config.synchroniser.image_interval_ns * 1e-9);
  request_deadline =
      count == 0 ? Clock::time_point::max()
                 : Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(count * sequence_s + 2.0));
  state = ScanState::kScanning;
  launch_at_ns = 0;
  try {
    if (active_trigger == TriggerMode::kHardware) {
      launchLocked(current_pattern, pattern->frameCount(), count);
    } else {
      generation++;  // the control thread acquires this generation's sets
      control_cv.notify_all();
    }
  } catch (const std::exception& e) {
    state = ScanState::kError;
    recorder.stop();
    recording_name.clear();
    last_error = std::string("projector: ") + e.what();
  }
  ++status_version;
}

// Carries out the pending pattern switch of a continuous hardware-triggered
// scan at the boundary after the sequence in progress: the projector starts
// the new pattern's schedule in the same request; the synchroniser lets the
// old pattern's last sequence complete (PatternEvent::previous_until_ns).
// Caller holds the mutex.
void ScanEngine::Impl::switchLocked() {
  const std::string name = std::exchange(switch_pattern, std::string());
  const pipeline::TimestampNs boundary = std::exchange(switch_at_ns, 0);
  switch_draining = false;
  try {
    devices.projector->select(name);
    current_pattern = name;
    pushControl({generation.load(), PatternEvent{name, config.findPattern(name)->frameCount(),
                                                 pipeline::systemClockNs(), boundary}});
    devices.projector->start(0);
  } catch (const std::exception& e) {
    finishRequestLocked(std::string("projector: ") + e.what());
    return;
  }
  ++status_version;
}

// Ends the current request; caller holds the mutex.
void ScanEngine::Impl::finishRequestLocked(const std::string& error) {
  try {
    devices.projector->stop();
  } catch (const std::exception& e) {
    last_error = std::string("projector stop: ") + e.what();
  }
  pushControl({generation.load(), EndEvent{!error.empty()}});
  generation++;
  state = ScanState::kIdle;
  launch_at_ns = 0;
  switch_pattern.clear();
  switch_draining = false;
  recorder.stop();
  recording_name.clear();
  if (!error.empty()) last_error = error;
  ++status_version;
}

void ScanEngine::Impl::recordError(const std::string& error) {
  std::lock_guard lock(mutex);
  last_error = error;
  ++status_version;
}

ScanEngine::ScanEngine(const DaemonConfig& config, EngineDevices devices, OutputCallback output)
    : impl_(std::make_unique<Impl>(config, std::move(devices), std::move(output))) {
  Impl& d = *impl_;
  d.heartbeats = std::vector<Heartbeat>(d.devices.cameras.size() + 5);
  d.last_frame_ns = std::make_unique<std::atomic<pipeline::TimestampNs>[]>(d.devices.cameras.size());
  for (std::size_t i = 0; i < d.devices.cameras.size(); ++i) d.last_frame_ns[i] = 0;
  for (std::size_t i = 0; i < d.devices.cameras.size(); ++i)
    d.threads.emplace_back([&d, i] { d.cameraLoop(i, d.heartbeats[i]); });
  const std::size_t k = d.devices.cameras.size();
  d.threads.emplace_back([&d, k] { d.triggerLoop(d.heartbeats[k]); });
  d.threads.emplace_back([&d, k] { d.syncLoop(d.heartbeats[k + 1]); });
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
  {
    // Under each mutex, so that no thread misses the wake-up between its
    // check of `running` and its wait.
    std::lock_guard lock(d.mutex);
    std::lock_guard gate(d.gate_mutex);
    d.running = false;
  }
  d.control_cv.notify_all();
  d.gate_cv.notify_all();
  for (auto& camera : d.devices.cameras) camera->stop();
  d.devices.trigger->stop();
  d.events.close();
  d.sets.close();
  d.results.close();
  for (auto& t : d.threads) t.join();
}

namespace {

bool validRecordingName(const std::string& name) {
  if (name.empty() || name == "." || name == ".." || name.size() > 128) return false;
  return name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.") ==
         std::string::npos;
}

std::string joined(const std::vector<std::string>& names) {
  std::string text;
  for (const auto& n : names) text += (text.empty() ? "" : ", ") + n;
  return text;
}

}  // namespace

CommandResult ScanEngine::start(const std::string& pattern, int count,
                                const std::string& recording) {
  StartRequest request;
  request.pattern = pattern;
  request.count = count;
  request.recording = recording;
  return start(request);
}

CommandResult ScanEngine::start(const StartRequest& request) {
  Impl& d = *impl_;
  using Code = CommandResult::Code;
  std::lock_guard lock(d.mutex);
  if (d.state == ScanState::kScanning || d.state == ScanState::kWaiting)
    return {Code::kBusy, std::string(d.state == ScanState::kWaiting ? "waiting to scan '"
                                                                     : "already scanning '") +
                             d.current_pattern + "' (" + std::to_string(d.scans_done) + " of " +
                             (d.scans_requested ? std::to_string(d.scans_requested)
                                                : std::string("continuous")) +
                             "); send stop first"};
  if (request.count < 0) return {Code::kInvalidCount, "count must be >= 0 (0 = continuous)"};
  const std::string name = request.pattern.empty() ? d.current_pattern : request.pattern;
  const pipeline::PatternSpec* pattern = d.config.findPattern(name);
  if (!pattern) return {Code::kUnknownPattern, "unknown pattern '" + name + "'"};

  // --- options ---
  const TriggerMode trigger = request.trigger.value_or(d.config.runtime.trigger);
  if (trigger == TriggerMode::kSoftware) {
    const std::string why = d.software.unsupportedReason();
    if (!why.empty()) return {Code::kUnsupported, "software trigger: " + why};
  }
  if (!(std::isfinite(request.delay_s) && request.delay_s >= 0 && request.delay_s <= 3600))
    return {Code::kInvalidOption, "delay must be 0..3600 s, not " + std::to_string(request.delay_s)};
  const pipeline::TimestampNs now = pipeline::systemClockNs();
  if (request.start_at_ns != 0 && request.delay_s > 0)
    return {Code::kInvalidOption, "give a delay or a start time, not both"};
  if (request.start_at_ns != 0 && request.start_at_ns < now - 1'000'000'000)
    return {Code::kInvalidOption, "the start time lies " +
                                      std::to_string((now - request.start_at_ns) / 1'000'000) +
                                      " ms in the past"};
  if (request.start_at_ns > now + 3600'000'000'000)
    return {Code::kInvalidOption, "the start time lies more than 3600 s ahead"};
  const std::vector<std::string>& configured = d.pattern_cameras.at(name);
  std::set<std::string> seen;
  for (const std::string& id : request.cameras) {
    if (!seen.insert(id).second) return {Code::kInvalidOption, "camera '" + id + "' given twice"};
    if (std::find(configured.begin(), configured.end(), id) != configured.end()) continue;
    const bool exists = std::any_of(d.devices.cameras.begin(), d.devices.cameras.end(),
                                    [&](const auto& c) { return c->id() == id; });
    return {Code::kInvalidOption,
            exists ? "camera '" + id + "' does not triangulate pattern '" + name +
                         "' (its cameras: " + joined(configured) + ")"
                   : "unknown camera '" + id + "' (pattern '" + name + "' has " +
                         joined(configured) + ")"};
  }

  if (!request.recording.empty()) {
    if (!validRecordingName(request.recording))
      return {Code::kInvalidCommand, "recording name '" + request.recording +
                                         "' must be letters, digits, '_', '-' or '.' (no paths)"};
    const std::string dir = d.config.runtime.recording_root + "/" + request.recording;
    try {
      d.recorder.start(dir, "pattern " + name + ", " + std::to_string(request.count) +
                                " scans requested");
    } catch (const std::exception& e) {
      return {Code::kDeviceError, std::string("cannot record: ") + e.what()};
    }
    d.recording_name = request.recording;
  }
  if (name != d.current_pattern) {
    try {
      d.devices.projector->select(name);
    } catch (const std::exception& e) {
      d.recorder.stop();
      d.recording_name.clear();
      d.last_error = std::string("projector: ") + e.what();
      ++d.status_version;
      return {Code::kDeviceError, d.last_error};
    }
    d.current_pattern = name;
  }
  auto options = std::make_shared<RequestOptions>();
  options->cameras_pattern = name;
  options->cameras = request.cameras;
  options->motion_compensation = request.motion_compensation;
  d.request_options = std::move(options);
  d.active_trigger = trigger;
  d.scans_requested = static_cast<std::uint64_t>(request.count);
  d.scans_done = 0;
  d.pending_count = request.count;
  d.last_error.clear();
  const pipeline::TimestampNs launch_at =
      request.start_at_ns != 0 ? request.start_at_ns
                               : now + static_cast<pipeline::TimestampNs>(request.delay_s * 1e9);
  if (launch_at > now) {
    d.state = ScanState::kWaiting;  // the control thread begins it
    d.launch_at_ns = launch_at;
    d.control_cv.notify_all();
    ++d.status_version;
    return {};
  }
  d.beginLocked();
  if (d.state == ScanState::kError) return {Code::kDeviceError, d.last_error};
  return {};
}

CommandResult ScanEngine::stop() {
  Impl& d = *impl_;
  std::lock_guard lock(d.mutex);
  if (d.state != ScanState::kScanning && d.state != ScanState::kWaiting)
    return {CommandResult::Code::kNotRunning, "not scanning"};
  d.finishRequestLocked("");
  return {};
}

CommandResult ScanEngine::selectPattern(const std::string& name) {
  Impl& d = *impl_;
  using Code = CommandResult::Code;
  std::lock_guard lock(d.mutex);
  const pipeline::PatternSpec* pattern = d.config.findPattern(name);
  if (!pattern) return {Code::kUnknownPattern, "unknown pattern '" + name + "'"};
  const bool scanning = d.state == ScanState::kScanning;
  if ((scanning || d.state == ScanState::kWaiting) && d.scans_requested != 0)
    return {Code::kBusy, "cannot switch pattern during a request of " +
                             std::to_string(d.scans_requested) +
                             " scans; wait for it or send stop (continuous scans switch)"};
  if (scanning && d.active_trigger == TriggerMode::kSoftware) {
    // The control thread reads the pattern at each sequence boundary: the
    // sequence in progress completes with the old pattern.
    d.current_pattern = name;
    ++d.status_version;
    return {};
  }
  if (scanning) {
    // Continuous hardware-triggered scan: the control thread switches at the
    // end of the sequence in progress (a sequence of the running pattern
    // starts every frame_count image intervals from the last trigger).
    // Before the first trigger there is nothing to finish: switch now. A
    // later request replaces a switch still pending.
    if (d.switch_draining) {  // the projector already stopped at the boundary
      d.switch_pattern = name;
      return {};
    }
    if (!d.switch_pattern.empty() && name == d.current_pattern) {
      // Back to the running pattern before the pending switch happened:
      // cancel it and release the boundary hold.
      d.switch_pattern.clear();
      d.pushControl(
          {d.generation.load(), BoundaryEvent{std::numeric_limits<pipeline::TimestampNs>::max()}});
      return {};
    }
    if (name == d.current_pattern) return {};
    const pipeline::TimestampNs period = d.config.findPattern(d.current_pattern)->frameCount() *
                                         d.config.synchroniser.image_interval_ns;
    const pipeline::TimestampNs last = d.last_trigger_ns.load();
    const pipeline::TimestampNs now = pipeline::systemClockNs();
    d.switch_at_ns = last > 0 && now >= last ? last + ((now - last) / period + 1) * period : now;
    d.switch_pattern = name;
    d.pushControl({d.generation.load(), BoundaryEvent{d.switch_at_ns}});
    d.control_cv.notify_all();
    return {};
  }
  try {
    d.devices.projector->select(name);
    d.current_pattern = name;
  } catch (const std::exception& e) {
    return {Code::kDeviceError, std::string("projector: ") + e.what()};
  }
  ++d.status_version;
  return {};
}

std::vector<std::string> ScanEngine::patterns() const {
  std::vector<std::string> names;
  for (const auto& p : impl_->config.patterns) names.push_back(p.name);
  return names;
}

const DaemonConfig& ScanEngine::config() const { return impl_->config; }

void ScanEngine::applyRuntimeSettings(const DaemonConfig& settings) {
  std::lock_guard lock(impl_->mutex);
  impl_->pending_settings = settings;
  impl_->settings_pending = true;
}

void ScanEngine::reportError(const std::string& message) { impl_->recordError(message); }

EngineStatus ScanEngine::status() const {
  const Impl& d = *impl_;
  EngineStatus s;
  std::lock_guard lock(d.mutex);
  s.version = d.status_version;
  s.state = d.state;
  s.pattern = d.current_pattern;
  s.scans_done = d.scans_done;
  s.scans_requested = d.scans_requested;
  s.scan_rate_hz = d.state == ScanState::kScanning ? d.scan_rate_hz : 0.0;
  s.frames_overflow = d.events.dropped();
  s.frames_unmatched = d.frames_unmatched.load() + d.software.staleFrames();
  s.frames_dropped = s.frames_overflow + s.frames_unmatched;
  s.sets_overflow = d.sets.dropped() + d.results.dropped();
  s.sets_not_recorded = d.recorder.dropped();
  s.sets_dropped = s.sets_overflow + s.sets_not_recorded;
  s.sets_incomplete = d.sets_incomplete.load();
  s.recording = d.recording_name;
  s.sets_recorded = d.recorder.written();
  const std::string recorder_error = d.recorder.lastError();
  s.last_error = recorder_error.empty() ? d.last_error : recorder_error;
  s.trigger = d.active_trigger;
  s.cameras = d.camerasFor(d.current_pattern, *d.request_options);
  s.motion_compensation = d.request_options->motion_compensation.value_or(d.motion_enabled.load());
  s.start_at_ns = d.state == ScanState::kWaiting ? d.launch_at_ns : 0;
  // Frame rate over windows of at least a second (status() is polled often).
  const auto now = Clock::now();
  const double window_s = std::chrono::duration<double>(now - d.rate_window_start).count();
  if (window_s >= 1.0) {
    const std::uint64_t frames = d.frames_received.load();
    d.frame_rate_hz = (frames - d.rate_window_frames) / window_s;
    d.rate_window_frames = frames;
    d.rate_window_start = now;
  }
  s.frame_rate_hz = d.frame_rate_hz;
  return s;
}

bool ScanEngine::healthy() const {
  for (const auto& hb : impl_->heartbeats)
    if (!hb.recent(2s)) return false;
  return true;
}

}  // namespace sl::daemon
