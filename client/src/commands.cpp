#include "sl/client/commands.h"

namespace sl::client {

const char* toString(TriggerMode mode) {
  return mode == TriggerMode::kSoftware ? "software" : "hardware";
}

const char* toString(ScanState s) {
  switch (s) {
    case ScanState::kIdle: return "idle";
    case ScanState::kScanning: return "scanning";
    case ScanState::kError: return "error";
    case ScanState::kWaiting: return "waiting";
    case ScanState::kDegraded: return "degraded";
  }
  return "?";
}

const char* toString(CommandResult::Code code) {
  switch (code) {
    case CommandResult::Code::kOk: return "ok";
    case CommandResult::Code::kUnknownPattern: return "unknown pattern";
    case CommandResult::Code::kBusy: return "busy";
    case CommandResult::Code::kInvalidCount: return "invalid count";
    case CommandResult::Code::kInvalidCommand: return "invalid command";
    case CommandResult::Code::kDeviceError: return "device error";
    case CommandResult::Code::kNotRunning: return "not running";
    case CommandResult::Code::kInvalidOption: return "invalid option";
    case CommandResult::Code::kUnsupported: return "unsupported";
  }
  return "?";
}

}  // namespace sl::client
