#include "engine/start_validation.h"

#include <algorithm>
#include <cmath>
#include <set>

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::CommandResult;
using ::sl::files::ConfigError;
using ::sl::client::ScanState;
using ::sl::client::StartRequest;
using ::sl::client::TriggerMode;

namespace {

std::string joined(const std::vector<std::string>& names) {
  std::string text;
  for (const auto& n : names) text += (text.empty() ? "" : ", ") + n;
  return text;
}

StartValidation rejected(CommandResult::Code code, std::string reason) {
  StartValidation v;
  v.rejection = {code, std::move(reason)};
  return v;
}

}  // namespace

std::map<std::string, std::vector<std::string>> checkedPatternCameras(
    const DaemonConfig& config, const std::vector<std::string>& camera_ids,
    const std::map<std::string, pipeline::CameraProjectorCalibration>& calibrations) {
  std::map<std::string, std::vector<std::string>> result;
  for (const auto& p : config.patterns) {
    const auto listed = config.pattern_cameras.find(p.name);
    const std::vector<std::string> ids = listed != config.pattern_cameras.end()
                                             ? listed->second
                                             : std::vector<std::string>{camera_ids.front()};
    // Config mistakes found only against the sensor's cameras: ConfigError,
    // so sl_sensord exits 2 (systemd does not restart it in a loop).
    for (const auto& id : ids)
      if (!calibrations.count(id))
        throw ConfigError(config.source_path + ": pattern '" + p.name + "' names camera '" +
                                 id + "', which the sensor lacks or which has no calibration "
                                 "(calibration: for the first camera, calibrations: for others)");
    result[p.name] = ids;
  }
  for (const auto& [pattern, id] : config.pattern_intensity_camera)
    if (!calibrations.count(id))
      throw ConfigError(config.source_path + ": pattern '" + pattern +
                        "' takes its intensity from camera '" + id +
                               "', which the sensor lacks or which has no calibration");
  return result;
}

bool validRecordingName(const std::string& name) {
  if (name.empty() || name == "." || name == ".." || name.size() > 128) return false;
  return name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.") ==
         std::string::npos;
}

StartValidation validateStart(const StartRequest& request, const StartContext& context) {
  using Code = CommandResult::Code;
  const DaemonConfig& config = *context.config;
  if (context.state == ScanState::kScanning || context.state == ScanState::kWaiting)
    return rejected(Code::kBusy,
                    std::string(context.state == ScanState::kWaiting ? "waiting to scan '"
                                                                     : "already scanning '") +
                        context.current_pattern + "' (" + std::to_string(context.scans_done) +
                        " of " +
                        (context.scans_requested ? std::to_string(context.scans_requested)
                                                 : std::string("continuous")) +
                        "); send stop first");
  if (request.count < 0) return rejected(Code::kInvalidCount, "count must be >= 0 (0 = continuous)");
  const std::string name = request.pattern.empty() ? context.current_pattern : request.pattern;
  if (!config.findPattern(name)) return rejected(Code::kUnknownPattern, "unknown pattern '" + name + "'");

  const TriggerMode trigger = request.trigger.value_or(config.runtime.trigger);
  if (trigger == TriggerMode::kSoftware && !context.software_unsupported.empty())
    return rejected(Code::kUnsupported, "software trigger: " + context.software_unsupported);
  if (!(std::isfinite(request.delay_s) && request.delay_s >= 0 && request.delay_s <= 3600))
    return rejected(Code::kInvalidOption,
                    "delay must be 0..3600 s, not " + std::to_string(request.delay_s));
  const pipeline::TimestampNs now = context.now_ns;
  if (request.start_at_ns != 0 && request.delay_s > 0)
    return rejected(Code::kInvalidOption, "give a delay or a start time, not both");
  if (request.start_at_ns != 0 && request.start_at_ns < now - 1'000'000'000)
    return rejected(Code::kInvalidOption,
                    "the start time lies " + std::to_string((now - request.start_at_ns) / 1'000'000) +
                        " ms in the past");
  if (request.start_at_ns > now + 3600'000'000'000)
    return rejected(Code::kInvalidOption, "the start time lies more than 3600 s ahead");

  const std::vector<std::string>& configured = context.pattern_cameras->at(name);
  std::set<std::string> seen;
  for (const std::string& id : request.cameras) {
    if (!seen.insert(id).second) return rejected(Code::kInvalidOption, "camera '" + id + "' given twice");
    if (std::find(configured.begin(), configured.end(), id) != configured.end()) continue;
    const bool exists =
        std::find(context.camera_ids.begin(), context.camera_ids.end(), id) != context.camera_ids.end();
    return rejected(Code::kInvalidOption,
                    exists ? "camera '" + id + "' does not triangulate pattern '" + name +
                                 "' (its cameras: " + joined(configured) + ")"
                           : "unknown camera '" + id + "' (pattern '" + name + "' has " +
                                 joined(configured) + ")");
  }
  if (!request.recording.empty() && !validRecordingName(request.recording))
    return rejected(Code::kInvalidCommand, "recording name '" + request.recording +
                                               "' must be letters, digits, '_', '-' or '.' (no paths)");

  StartValidation v;
  AcceptedStart& s = v.start;
  s.pattern = name;
  s.count = request.count;
  s.trigger = trigger;
  s.recording = request.recording;
  if (!s.recording.empty()) s.recording_dir = config.runtime.recording_root + "/" + s.recording;
  s.launch_at_ns = request.start_at_ns != 0
                       ? request.start_at_ns
                       : now + static_cast<pipeline::TimestampNs>(request.delay_s * 1e9);
  s.options.cameras_pattern = name;
  s.options.cameras = request.cameras;
  s.options.motion_compensation = request.motion_compensation;
  return v;
}

}  // namespace sl::daemon
