#include "engine/request_control.h"

#include <algorithm>
#include <cstdio>
#include <limits>
#include <utility>

#include "engine/start_validation.h"
#include "sl/daemon/log.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::client::ScanState;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;

using namespace std::chrono_literals;

RequestControl::RequestControl(const DaemonConfig& config, Links links)
    : config_(config), links_(std::move(links)), trigger_(config.runtime.trigger) {
  current_pattern_ = config.runtime.default_pattern;
  links_.projector->select(current_pattern_);
}

CommandResult RequestControl::start(const StartRequest& request) {
  using Code = CommandResult::Code;
  std::lock_guard lock(mutex_);
  StartContext context;
  context.config = &config_;
  context.state = state_;
  context.current_pattern = current_pattern_;
  context.scans_done = scans_done_;
  context.scans_requested = scans_requested_;
  context.pattern_cameras = &links_.pattern_cameras;
  context.camera_ids = links_.camera_ids;
  context.software_unsupported = links_.software_unsupported;
  context.now_ns = pipeline::systemClockNs();
  const StartValidation validation = validateStart(request, context);
  if (!validation.accepted()) return validation.rejection;
  const AcceptedStart& accepted = validation.start;
  // An accepted recording names its folder in the reply.
  const CommandResult ok{Code::kOk,
                         accepted.recording.empty() ? "" : "recording to " + accepted.recording_dir};

  if (!accepted.recording.empty()) {
    try {
      links_.recorder->start(accepted.recording_dir, "pattern " + accepted.pattern + ", " +
                                                         std::to_string(accepted.count) +
                                                         " scans requested",
                                 config_.patterns);
    } catch (const std::exception& e) {
      return {Code::kDeviceError, std::string("cannot record: ") + e.what()};
    }
    recording_ = accepted.recording;
  }
  if (accepted.pattern != current_pattern_) {
    try {
      links_.projector->select(accepted.pattern);
    } catch (const std::exception& e) {
      links_.recorder->stop();
      recording_.clear();
      setErrorLocked(std::string("projector: ") + e.what(), "");
      ++status_version_;
      return {Code::kDeviceError, last_error_};
    }
    current_pattern_ = accepted.pattern;
  }
  options_ = std::make_shared<RequestOptions>(accepted.options);
  trigger_ = accepted.trigger;
  scans_requested_ = static_cast<std::uint64_t>(accepted.count);
  scans_done_ = 0;
  pending_count_ = accepted.count;
  last_error_.clear();
  error_source_.clear();
  last_error_ns_ = 0;
  if (accepted.launch_at_ns > context.now_ns) {
    state_ = ScanState::kWaiting;  // the control thread begins it
    launch_at_ns_ = accepted.launch_at_ns;
    changed_.notify_all();
    ++status_version_;
    return ok;
  }
  beginLocked();
  if (state_ == ScanState::kError) return {Code::kDeviceError, last_error_};
  return ok;
}

CommandResult RequestControl::stop() {
  std::lock_guard lock(mutex_);
  if (state_ != ScanState::kScanning && state_ != ScanState::kWaiting)
    return {CommandResult::Code::kNotRunning, "not scanning"};
  finishLocked("");
  return {};
}

CommandResult RequestControl::selectPattern(const std::string& name) {
  using Code = CommandResult::Code;
  std::lock_guard lock(mutex_);
  if (!config_.findPattern(name)) return {Code::kUnknownPattern, "unknown pattern '" + name + "'"};
  const bool scanning = state_ == ScanState::kScanning;
  if ((scanning || state_ == ScanState::kWaiting) && scans_requested_ != 0)
    return {Code::kBusy, "cannot switch pattern during a request of " +
                             std::to_string(scans_requested_) +
                             " scans; wait for it or send stop (continuous scans switch)"};
  if (scanning && trigger_ == TriggerMode::kSoftware) {
    // The control thread reads the pattern at each sequence boundary: the
    // sequence in progress completes with the old pattern.
    current_pattern_ = name;
    ++status_version_;
    return {};
  }
  if (scanning) {
    // Continuous hardware-triggered scan: the control thread switches at the
    // end of a complete sequence of the running schedule (switchTimeLocked).
    // A request while a switch is pending replaces its pattern but keeps its
    // time, so that a storm of requests delays switches and never stops the
    // projector before a sequence completes.
    if (!switch_pattern_.empty() && name == current_pattern_ && !switch_draining_) {
      // Back to the running pattern before the pending switch happened:
      // cancel it and release the boundary hold.
      switch_pattern_.clear();
      if (switch_at_ns_ != 0)
        tellSchedule({generation_.load(), SwitchPending{std::numeric_limits<pipeline::TimestampNs>::max()}});
      switch_at_ns_ = 0;
      return {};
    }
    if (!switch_pattern_.empty()) {
      switch_pattern_ = name;
      noteSwitchDelayedLocked();
      return {};
    }
    if (name == current_pattern_) return {};
    switch_pattern_ = name;
    switch_at_ns_ = 0;
    switch_replaced_ = false;
    switchTimeLocked(pipeline::systemClockNs());
    changed_.notify_all();
    return {};
  }
  try {
    links_.projector->select(name);
    current_pattern_ = name;
  } catch (const std::exception& e) {
    return {Code::kDeviceError, std::string("projector: ") + e.what()};
  }
  ++status_version_;
  return {};
}

bool RequestControl::serviceTimers() {
  std::unique_lock lock(mutex_);
  if (shut_down_) return false;
  if (state_ == ScanState::kWaiting) {
    const pipeline::TimestampNs now = pipeline::systemClockNs();
    if (now >= launch_at_ns_) {
      beginLocked();
    } else {
      changed_.wait_for(lock, std::min<std::chrono::nanoseconds>(
                                  100ms, std::chrono::nanoseconds(launch_at_ns_ - now)));
    }
    return true;
  }
  if (state_ != ScanState::kScanning || switch_pattern_.empty()) return false;
  const pipeline::TimestampNs now = pipeline::systemClockNs();
  if (switch_at_ns_ == 0 && !switchTimeLocked(now)) {
    changed_.wait_for(lock, 5ms);  // until the running schedule's first trigger
    return true;
  }
  if (switch_draining_) {
    // The old pattern's last frame is exposed one image interval before the
    // boundary (half an interval of slack for stamp jitter).
    const pipeline::TimestampNs last_frame = switch_at_ns_ - 3 * config_.synchroniser.image_interval_ns / 2;
    if (links_.cameras_reached(last_frame) || Clock::now() >= drain_until_) {
      switchLocked();
    } else {
      changed_.wait_for(lock, 2ms);
    }
  } else if (now >= switch_at_ns_) {
    try {
      links_.projector->stop();
    } catch (const std::exception& e) {
      switch_pattern_.clear();
      finishLocked(std::string("projector: ") + e.what());
      return true;
    }
    switch_draining_ = true;
    drain_until_ = Clock::now() + 300ms;
  } else {
    changed_.wait_for(lock, std::min<std::chrono::nanoseconds>(
                                100ms, std::chrono::nanoseconds(switch_at_ns_ - now)));
  }
  return true;
}

void RequestControl::waitForChange(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  if (!shut_down_) changed_.wait_for(lock, timeout);
}

std::optional<RequestControl::SoftwareRun> RequestControl::softwareRun() const {
  std::lock_guard lock(mutex_);
  if (state_ != ScanState::kScanning || trigger_ != TriggerMode::kSoftware) return std::nullopt;
  SoftwareRun run{generation_.load(), current_pattern_,
                  config_.findPattern(current_pattern_)->frameCount(), scans_requested_, {}};
  if (recording_.empty()) {
    run.cameras = camerasFor(current_pattern_, *options_);
    if (const auto it = config_.pattern_intensity_camera.find(current_pattern_);
        it != config_.pattern_intensity_camera.end() &&
        std::find(run.cameras.begin(), run.cameras.end(), it->second) == run.cameras.end())
      run.cameras.push_back(it->second);
  }
  return run;
}

std::optional<std::uint64_t> RequestControl::countScan(std::uint64_t generation) {
  std::lock_guard lock(mutex_);
  if (generation != generation_.load() || state_ != ScanState::kScanning) return std::nullopt;
  ++scans_done_;
  // Software-triggered sets come as fast as the devices allow: the deadline
  // follows progress (as long as a scan arrives every sequence_s + lateS(),
  // nothing is lost).
  if (trigger_ == TriggerMode::kSoftware && scans_requested_ > scans_done_)
    deadline_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
                                   (scans_requested_ - scans_done_) * sequence_s_ + lateS()));
  ++status_version_;
  return scans_done_;
}

void RequestControl::finishIfComplete(std::uint64_t generation) {
  std::lock_guard lock(mutex_);
  if (generation == generation_.load() && scans_requested_ != 0 && scans_done_ >= scans_requested_)
    finishLocked("");
}

void RequestControl::checkDeadline(bool sets_in_flight) {
  std::lock_guard lock(mutex_);
  if (state_ == ScanState::kScanning && !sets_in_flight && Clock::now() > deadline_)
    finishLocked("request ended with " + std::to_string(scans_done_) + " of " +
                 std::to_string(scans_requested_) +
                 " scans: image sets were lost (see the drop counters)");
}

void RequestControl::endRequest(std::uint64_t generation, const std::string& error) {
  std::lock_guard lock(mutex_);
  if (generation == generation_.load()) finishLocked(error);
}

void RequestControl::reportError(const std::string& message, const std::string& source) {
  std::lock_guard lock(mutex_);
  const bool repeat = message == last_error_ && source == error_source_;
  setErrorLocked(message, source);
  if (!repeat) ++status_version_;
}

void RequestControl::setErrorLocked(const std::string& message, const std::string& source) {
  last_error_ = message;
  error_source_ = source;
  last_error_ns_ = pipeline::systemClockNs();
  ++errors_reported_;
}

void RequestControl::clearError(const std::string& source_prefix) {
  std::lock_guard lock(mutex_);
  if (source_prefix.empty() || last_error_.empty() ||
      error_source_.compare(0, source_prefix.size(), source_prefix) != 0)
    return;
  last_error_.clear();
  error_source_.clear();
  last_error_ns_ = 0;
  ++status_version_;
}

RequestControl::Health RequestControl::health() const {
  std::lock_guard lock(mutex_);
  return {state_ == ScanState::kScanning, trigger_, scanning_since_, sequence_s_, scans_requested_};
}

void RequestControl::setDegraded(const std::string& cause) {
  std::lock_guard lock(mutex_);
  if (state_ != ScanState::kScanning || cause == degraded_reason_) return;
  // The same cause with a longer duration: updated, but no new version (the
  // periodic status shows it).
  auto withoutNumbers = [](std::string text) {
    text.erase(std::remove_if(text.begin(), text.end(), [](char c) { return (c >= '0' && c <= '9') || c == '.'; }),
               text.end());
    return text;
  };
  if (!cause.empty() && !degraded_reason_.empty() && withoutNumbers(cause) == withoutNumbers(degraded_reason_)) {
    degraded_reason_ = cause;
    return;
  }
  if (!cause.empty() && degraded_reason_.empty()) {
    degraded_since_ = Clock::now();
    logWarning("degraded: " + cause);
    setErrorLocked("degraded: " + cause, "health");
  } else if (cause.empty()) {
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%.1f",
                  std::chrono::duration<double>(Clock::now() - degraded_since_).count());
    logInfo(std::string("recovered after ") + seconds + " s degraded (" + degraded_reason_ + ")");
    if (error_source_ == "health") {
      last_error_.clear();
      error_source_.clear();
      last_error_ns_ = 0;
    }
  }
  degraded_reason_ = cause;
  ++status_version_;
}

void RequestControl::touch() {
  std::lock_guard lock(mutex_);
  ++status_version_;
}

std::shared_ptr<const RequestOptions> RequestControl::options() const {
  std::lock_guard lock(mutex_);
  return options_;
}

std::vector<std::string> RequestControl::camerasFor(const std::string& pattern,
                                                    const RequestOptions& options) const {
  if (!options.cameras.empty() && options.cameras_pattern == pattern) return options.cameras;
  return links_.pattern_cameras.at(pattern);
}

void RequestControl::fillStatus(EngineStatus& s) const {
  std::lock_guard lock(mutex_);
  s.version = status_version_;
  s.state = state_;
  s.pattern = current_pattern_;
  s.scans_done = scans_done_;
  s.scans_requested = scans_requested_;
  s.degraded_reason = state_ == ScanState::kScanning ? degraded_reason_ : "";
  if (!s.degraded_reason.empty()) s.state = ScanState::kDegraded;
  const double hold_ns = config_.runtime.last_error_hold_s * 1e9;
  const bool aged = hold_ns > 0 && last_error_ns_ > 0 &&
                    static_cast<double>(pipeline::systemClockNs() - last_error_ns_) > hold_ns;
  s.last_error = aged ? "" : last_error_;
  s.last_error_ns = aged ? 0 : last_error_ns_;
  s.errors_reported = errors_reported_;
  s.recording = recording_;
  s.trigger = trigger_;
  s.cameras = camerasFor(current_pattern_, *options_);
  s.start_at_ns = state_ == ScanState::kWaiting ? launch_at_ns_ : 0;
}

void RequestControl::shutDown() {
  {
    std::lock_guard lock(mutex_);
    shut_down_ = true;
  }
  changed_.notify_all();
}

// Decides when the pending switch happens, once the running schedule has
// delivered its first trigger: at the end of the sequence in progress (its
// sequences start every frame_count image intervals from its latest
// trigger), so that every schedule completes at least one sequence. Without
// a trigger of the running schedule for two sequences plus the grouping's
// max_age (a silent trigger source), the switch happens now. False while
// still waiting for the first trigger.
bool RequestControl::switchTimeLocked(pipeline::TimestampNs now) {
  const pipeline::TimestampNs period =
      config_.findPattern(current_pattern_)->frameCount() * config_.synchroniser.image_interval_ns;
  const pipeline::TimestampNs last = links_.last_trigger_ns();
  if (last > 0 && last >= schedule_start_ns_) {  // older triggers are an earlier schedule's
    switch_at_ns_ = now >= last ? last + ((now - last) / period + 1) * period : last + period;
  } else if (now >= schedule_start_ns_ + 2 * period + config_.synchroniser.max_age_ns) {
    switch_at_ns_ = now;
  } else {
    return false;
  }
  tellSchedule({generation_.load(), SwitchPending{switch_at_ns_}});
  return true;
}

// A request replaced a pending switch: requests come faster than the running
// pattern completes its sequences. Said once in last_error (repeats refresh
// its time and count); cleared by a switch that no request replaced.
void RequestControl::noteSwitchDelayedLocked() {
  static const std::string kMessage =
      "pattern switches delayed: requests come faster than the running pattern completes a "
      "sequence; each switch waits for one, the latest request wins";
  switch_replaced_ = true;
  const bool repeat = last_error_ == kMessage && error_source_ == "switch";
  setErrorLocked(kMessage, "switch");
  if (!repeat) ++status_version_;
}

// Starts a new projector schedule of `count` sequences (0 = until stop) of
// pattern `name` as a new generation. Throws what the projector throws.
void RequestControl::launchLocked(const std::string& name, int frame_count, int count) {
  const std::uint64_t next = generation_.load() + 1;
  links_.projector->select(name);
  current_pattern_ = name;
  schedule_start_ns_ = pipeline::systemClockNs();
  tellSchedule({next, RunStarted{name, frame_count, schedule_start_ns_}});
  generation_ = next;
  links_.projector->start(count);
}

// Begins the accepted request (kWaiting until now) with current_pattern_ and
// pending_count_. A device error ends it in kError.
void RequestControl::beginLocked() {
  const pipeline::PatternSpec* pattern = config_.findPattern(current_pattern_);
  const int count = pending_count_;
  scans_done_ = 0;
  // Time per sequence: one image interval per pattern with a trigger board;
  // in software, settle plus (at least) an exposure per pattern, doubled
  // for transfer and processing, and at most settle plus the grab timeout
  // per pattern (a slower image fails the acquisition itself, which is
  // reported): a slow camera is not taken for lost sets.
  sequence_s_ = pattern->frameCount() * config_.synchroniser.image_interval_ns * 1e-9;
  if (trigger_ == TriggerMode::kSoftware)
    sequence_s_ = pattern->frameCount() *
                  std::max(2 * (config_.software_trigger.settle_s +
                                config_.synchroniser.image_interval_ns * 1e-9),
                           config_.software_trigger.settle_s + config_.software_trigger.grab_timeout_s);
  deadline_ = count == 0 ? Clock::time_point::max()
                         : Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                              std::chrono::duration<double>(count * sequence_s_ + lateS()));
  state_ = ScanState::kScanning;
  scanning_since_ = Clock::now();
  degraded_reason_.clear();
  launch_at_ns_ = 0;
  try {
    if (trigger_ == TriggerMode::kHardware) {
      launchLocked(current_pattern_, pattern->frameCount(), count);
    } else {
      generation_++;  // the control thread acquires this generation's sets
      changed_.notify_all();
    }
  } catch (const std::exception& e) {
    state_ = ScanState::kError;
    links_.recorder->stop();
    recording_.clear();
    setErrorLocked(std::string("projector: ") + e.what(), "");
  }
  ++status_version_;
}

// Carries out the pending pattern switch of a continuous hardware-triggered
// scan at the boundary after the sequence in progress: the projector starts
// the new pattern's schedule in the same request; the grouping lets the old
// pattern's last sequence complete (PatternSwitched::boundary_ns).
void RequestControl::switchLocked() {
  const std::string name = std::exchange(switch_pattern_, std::string());
  const pipeline::TimestampNs boundary = std::exchange(switch_at_ns_, 0);
  switch_draining_ = false;
  if (!std::exchange(switch_replaced_, false) && error_source_ == "switch") {
    last_error_.clear();
    error_source_.clear();
    last_error_ns_ = 0;
  }
  try {
    links_.projector->select(name);
    current_pattern_ = name;
    schedule_start_ns_ = pipeline::systemClockNs();
    tellSchedule({generation_.load(), PatternSwitched{name, config_.findPattern(name)->frameCount(),
                                                      schedule_start_ns_, boundary}});
    links_.projector->start(0);
  } catch (const std::exception& e) {
    finishLocked(std::string("projector: ") + e.what());
    return;
  }
  ++status_version_;
}

void RequestControl::finishLocked(const std::string& error) {
  try {
    links_.projector->stop();
  } catch (const std::exception& e) {
    setErrorLocked(std::string("projector stop: ") + e.what(), "");
  }
  tellSchedule({generation_.load(), RunEnded{!error.empty()}});
  generation_++;
  state_ = ScanState::kIdle;
  launch_at_ns_ = 0;
  switch_pattern_.clear();
  switch_at_ns_ = 0;
  switch_draining_ = false;
  links_.recorder->stop();
  recording_.clear();
  if (!error.empty()) setErrorLocked(error, "");
  degraded_reason_.clear();
  ++status_version_;
  changed_.notify_all();
}

}  // namespace sl::daemon
