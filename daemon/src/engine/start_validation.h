// Checking a start request against the configuration and the engine's state,
// before anything is touched. A pure function: the caller passes everything
// it reads (including the time), so that it is tested without devices.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "engine/schedule_events.h"
#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::client::ScanState;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;

// What validation reads besides the request.
struct StartContext {
  const DaemonConfig* config = nullptr;
  ScanState state = ScanState::kIdle;
  std::string current_pattern;
  std::uint64_t scans_done = 0;
  std::uint64_t scans_requested = 0;
  // Cameras that triangulate each pattern, and every camera of the sensor.
  const std::map<std::string, std::vector<std::string>>* pattern_cameras = nullptr;
  std::vector<std::string> camera_ids;
  std::string software_unsupported;  // why the devices cannot be software-triggered ("" = they can)
  pipeline::TimestampNs now_ns = 0;  // system clock
};

// A start request as accepted: the values to carry out.
struct AcceptedStart {
  std::string pattern;
  int count = 0;
  TriggerMode trigger = TriggerMode::kHardware;
  std::string recording;      // "" = none
  std::string recording_dir;  // <runtime.recording_root>/<recording>
  pipeline::TimestampNs launch_at_ns = 0;  // system clock; <= now: start at once
  RequestOptions options;
};

// Either the accepted start or the rejection (a code and a reason naming the
// option).
struct StartValidation {
  CommandResult rejection;
  AcceptedStart start;
  bool accepted() const { return rejection.accepted(); }
};

StartValidation validateStart(const StartRequest& request, const StartContext& context);

// Which cameras triangulate each pattern (`patterns[].cameras`, default the
// first camera); each of them and every intensity camera must be one of
// `camera_ids` with an entry in `calibrations`. Throws std::runtime_error
// naming the config file, the pattern and the camera.
std::map<std::string, std::vector<std::string>> checkedPatternCameras(
    const DaemonConfig& config, const std::vector<std::string>& camera_ids,
    const std::map<std::string, pipeline::CameraProjectorCalibration>& calibrations);

// Letters, digits, '_', '-', '.', at most 128, not "." or "..": a folder name
// that cannot leave runtime.recording_root.
bool validRecordingName(const std::string& name);

}  // namespace sl::daemon
