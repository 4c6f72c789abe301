#include "engine/device_health.h"

#include <algorithm>
#include <chrono>
#include <cstdio>

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::TriggerMode;

namespace {

std::string secondsText(double s) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f", s);
  return text;
}

}  // namespace

std::int64_t steadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

DeviceHealth::DeviceHealth(std::vector<std::string> camera_ids)
    : camera_ids_(std::move(camera_ids)),
      camera_seen_(camera_ids_.size()),
      camera_errors_(camera_ids_.size()) {}

void DeviceHealth::cameraFailed(std::size_t camera, const std::string& what) {
  std::lock_guard lock(mutex_);
  camera_errors_[camera] = what;
}

void DeviceHealth::triggerFailed(const std::string& what) {
  std::lock_guard lock(mutex_);
  trigger_error_ = what;
}

bool DeviceHealth::cameraDelivered(std::size_t camera, std::int64_t now_ns) {
  camera_seen_[camera] = now_ns;
  std::lock_guard lock(mutex_);
  const bool had_error = !camera_errors_[camera].empty();
  camera_errors_[camera].clear();
  return had_error;
}

bool DeviceHealth::triggerDelivered(std::int64_t now_ns) {
  trigger_seen_ = now_ns;
  std::lock_guard lock(mutex_);
  const bool had_error = !trigger_error_.empty();
  trigger_error_.clear();
  return had_error;
}

std::string DeviceHealth::silentDevices(std::int64_t since_ns, std::int64_t now_ns, double stall_s) const {
  auto silentFor = [&](std::int64_t seen_ns) { return (now_ns - std::max(seen_ns, since_ns)) * 1e-9; };
  std::string cause;
  auto add = [&](const std::string& text) { cause += (cause.empty() ? "" : "; ") + text; };
  std::lock_guard lock(mutex_);
  for (std::size_t i = 0; i < camera_ids_.size(); ++i) {
    const double silent = silentFor(camera_seen_[i].load());
    if (silent >= stall_s)
      add("camera '" + camera_ids_[i] + "': no frame for " + secondsText(silent) + " s" +
          (camera_errors_[i].empty() ? "" : " (" + camera_errors_[i] + ")"));
  }
  const double silent = silentFor(trigger_seen_.load());
  if (silent >= stall_s)
    add("trigger source: no trigger for " + secondsText(silent) + " s" +
        (trigger_error_.empty() ? "" : " (" + trigger_error_ + ")"));
  return cause;
}

std::string degradedCause(const RequestControl::Health& h, const DeviceHealth& devices,
                          const EngineStatistics& statistics, std::uint64_t generation, double stall_s) {
  using Clock = std::chrono::steady_clock;
  if (!h.scanning) return "";
  const std::int64_t since_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(h.since.time_since_epoch()).count();
  // A finite request's schedule ends after its sequences (the projector
  // stops): silence after that is no fault, so it is measured up to the end.
  std::int64_t until_ns = steadyNowNs();
  if (h.scans_requested > 0)
    until_ns = std::min(until_ns, since_ns + static_cast<std::int64_t>(1e9 * h.sequence_s *
                                                                       static_cast<double>(h.scans_requested)));
  std::string cause =
      h.trigger == TriggerMode::kHardware ? devices.silentDevices(since_ns, until_ns, stall_s) : "";
  const std::optional<Clock::time_point> last = statistics.lastScan(generation);
  const double no_scan_s =
      std::chrono::duration<double>(Clock::now() - std::max(last.value_or(h.since), h.since)).count();
  if (no_scan_s >= stall_s + h.sequence_s) {
    const std::uint64_t incomplete = last ? statistics.incompleteSinceLastScan() : 0;
    cause += (cause.empty() ? "" : "; ") + ("no scan published for " + secondsText(no_scan_s) + " s" +
                                            (incomplete > 0 ? " (" + std::to_string(incomplete) +
                                                                  " sequences incomplete)"
                                                            : ""));
  }
  return cause;
}

}  // namespace sl::daemon
