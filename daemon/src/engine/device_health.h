// Whether a running scan is healthy: when each camera last delivered a frame
// and the trigger source a trigger, their latest errors, and from these and
// the scans published, why the scan is degraded (README "Under faults").
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "engine/request_control.h"
#include "engine/statistics.h"

namespace sl::daemon {

// Thread-safe: each camera thread reports its own camera, the trigger thread
// the trigger source; the output thread asks. Times are steady-clock ns.
class DeviceHealth {
 public:
  explicit DeviceHealth(std::vector<std::string> camera_ids);

  // A grab / wait for a trigger failed with `what` (kept until it delivers).
  void cameraFailed(std::size_t camera, const std::string& what);
  void triggerFailed(const std::string& what);
  // A frame / trigger arrived at `now_ns`; true when that ends an error
  // reported before (the caller clears it from the status).
  bool cameraDelivered(std::size_t camera, std::int64_t now_ns);
  bool triggerDelivered(std::int64_t now_ns);

  // The devices silent for `stall_s` or longer at `now_ns`, counting from
  // `since_ns` at the earliest, each with its latest error; "" = none.
  std::string silentDevices(std::int64_t since_ns, std::int64_t now_ns, double stall_s) const;

 private:
  const std::vector<std::string> camera_ids_;
  std::vector<std::atomic<std::int64_t>> camera_seen_;  // 0 = never
  std::atomic<std::int64_t> trigger_seen_{0};
  mutable std::mutex mutex_;
  std::vector<std::string> camera_errors_;  // guarded by mutex_
  std::string trigger_error_;               // guarded by mutex_
};

// Why the scan `h` describes is degraded ("" = it is not, or no scan runs):
// with the trigger board, a camera without frames or a trigger source
// without triggers for `stall_s` (within a finite request's schedule: after
// its last sequence the devices are silent by design); in either mode, no scan of `generation`
// published for `stall_s` plus a sequence's time (since the start or the
// last scan).
std::string degradedCause(const RequestControl::Health& h, const DeviceHealth& devices,
                          const EngineStatistics& statistics, std::uint64_t generation, double stall_s);

std::int64_t steadyNowNs();

}  // namespace sl::daemon
