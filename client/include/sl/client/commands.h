// What a client can ask of the sensor and what it hears back: the request
// vocabulary shared by the scan engine (which carries requests out), the DDS
// edge (which converts them from and to the wire) and the client library
// (which sends them). Plain values; no DDS, no threads.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "sl/pipeline/types.h"

namespace sl::client {

// How image sets are acquired. kHardware: the projector runs whole sequences
// and the images are grouped by trigger time (trigger board or projector).
// kSoftware: the daemon shows pattern i, waits, grabs one image per camera
// (setups without a trigger board; slower).
enum class TriggerMode { kHardware, kSoftware };
const char* toString(TriggerMode mode);

// kWaiting: a start request was accepted and waits for its start time.
// kDegraded: scanning, but a device or the request stalled
// (EngineStatus::degraded_reason; runtime.stall_timeout_s); it returns to
// kScanning by itself when the cause goes away.
enum class ScanState { kIdle, kScanning, kError, kWaiting, kDegraded };
const char* toString(ScanState s);

// Outcome of a control request; `code` mirrors the DDS reply codes.
struct CommandResult {
  enum class Code { kOk, kUnknownPattern, kBusy, kInvalidCount, kInvalidCommand, kDeviceError,
                    kNotRunning, kInvalidOption, kUnsupported };
  Code code = Code::kOk;
  std::string reason;
  bool accepted() const { return code == Code::kOk; }
};
const char* toString(CommandResult::Code code);

// One start request. The optional fields left empty keep the configured
// behaviour.
struct StartRequest {
  std::string pattern;        // empty = the current pattern
  int count = 1;              // scans, 0 = until stop
  std::string recording;      // also record the image sets under this name ("" = no)
  std::optional<TriggerMode> trigger;  // default: runtime.trigger
  double delay_s = 0;         // start this long after the request, [0, 3600] s
  pipeline::TimestampNs start_at_ns = 0;  // or at this time (system clock); 0 = now
  // Cameras that triangulate `pattern`: a subset of its configured cameras
  // (empty = all). The subset applies to that pattern only: after a switch
  // to another pattern, that pattern's configured cameras triangulate.
  std::vector<std::string> cameras;
  std::optional<bool> motion_compensation;  // default: motion_compensation.enabled
};

}  // namespace sl::client
