#include "sl/daemon/devices.h"

#include <filesystem>
#include <map>
#include <set>
#include <stdexcept>

#if SL_HAVE_ARAVIS
#include "aravis_devices.h"
#endif
#include "sl/daemon/log.h"
#include "sl/files/pattern_config.h"
#include "sl/drivers/camera_stamp_trigger.h"
#include "sl/drivers/lightcrafter4500.h"
#include "sl/drivers/recording.h"
#include "sl/drivers/replay.h"
#include "sl/drivers/sim.h"
#include "sl/drivers/versavis.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::loadPattern;
using ::sl::files::patternDifferences;

namespace {

EngineDevices openSimulated(const DaemonConfig& config, std::shared_ptr<void>& keep_alive) {
  std::shared_ptr<drivers::SimulatedSensor> sim;
  try {
    sim = drivers::SimulatedSensor::create(config.sim);
  } catch (const std::exception& e) {
    throw std::runtime_error(config.source_path + ": simulated sensor: " + e.what());
  }
  // A static scene renders each pattern frame from its noise-free image,
  // computed on first use: compute them all now, so that the first sequence
  // of a scan renders as fast as the later ones (the live camera would
  // otherwise fall behind on it and drop it).
  if (!config.sim.motion.moving()) {
    for (const drivers::ProjectorSequence& s : sim->projector()->sequences())
      for (int frame = 0; frame < s.frame_count; ++frame)
        for (int camera = 0; camera < static_cast<int>(sim->cameras().size()); ++camera)
          sim->render(camera, s.name, frame, 0);
  }
  keep_alive = sim;
  EngineDevices devices;
  devices.cameras = sim->cameras();  // the first, then the optional second camera
  devices.projector = sim->projector();
  devices.trigger = sim->triggerSource();
  return devices;
}

// A recording folder's sets that keep their pattern's description
// (pattern.yml, drivers/recording.h) must describe the config's pattern of
// that name: the first such set of each pattern is compared key by key
// (`patterns` recorded patterns in all; an MCAP recording has no
// descriptions). Throws std::runtime_error naming the set's file, the
// pattern and every difference.
void checkRecordedPatterns(const DaemonConfig& config, std::size_t patterns) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(config.replay.dir)) return;
  std::set<std::string> checked;
  for (const std::string& set : drivers::listRecordedSets(config.replay.dir)) {
    if (checked.size() >= patterns) return;
    const fs::path described = fs::path(set) / drivers::kRecordedPatternFile;
    if (!fs::exists(described)) continue;
    const pipeline::PatternSpec recorded = loadPattern(described.string());
    if (!checked.insert(recorded.name).second) continue;
    const pipeline::PatternSpec* pattern = config.findPattern(recorded.name);
    if (!pattern) continue;  // a set of a pattern the projector's sequences do not list
    const std::vector<std::string> differences = patternDifferences(recorded, *pattern);
    if (differences.empty()) continue;
    std::string list;
    for (const std::string& d : differences) list += "; " + d;
    throw std::runtime_error(config.source_path + ": replay: " + described.string() +
                             " describes the recorded pattern '" + recorded.name +
                             "' otherwise than the config's pattern of that name (recorded vs "
                             "config" + list + ")");
  }
}

// A recording played back (sensor: replay). Every recorded pattern must be
// one the config can decode, as it was recorded.
EngineDevices openReplay(const DaemonConfig& config, std::shared_ptr<void>& keep_alive) {
  std::shared_ptr<drivers::ReplaySensor> replay;
  try {
    replay = drivers::ReplaySensor::open(config.replay);
  } catch (const std::exception& e) {
    throw std::runtime_error(config.source_path + ": replay: " + e.what());
  }
  keep_alive = replay;
  if (std::filesystem::is_directory(config.replay.dir))
    for (const std::string& skipped : drivers::incompleteRecordedSets(config.replay.dir))
      logWarning("replay: " + skipped);
  EngineDevices devices;
  devices.cameras = replay->cameras();
  devices.projector = replay->projector();
  devices.trigger = replay->triggerSource();
  const auto& camera = *devices.cameras.front();
  if (camera.width() != config.calibration.camera.width ||
      camera.height() != config.calibration.camera.height)
    throw std::runtime_error(config.source_path + ": replay: the recording's images are " +
                             std::to_string(camera.width()) + "x" +
                             std::to_string(camera.height()) + ", the calibration's camera " +
                             std::to_string(config.calibration.camera.width) + "x" +
                             std::to_string(config.calibration.camera.height));
  for (const auto& sequence : devices.projector->sequences())
    if (!config.findPattern(sequence.name))
      throw std::runtime_error(config.source_path + ": replay: the recording holds pattern '" +
                               sequence.name + "', which the config's patterns do not define");
  checkRecordedPatterns(config, devices.projector->sequences().size());
  return devices;
}

// The real sensor: cameras, LightCrafter 4500, VersaVIS or camera-stamp trigger times.
EngineDevices openHardware(const DaemonConfig& config) {
  EngineDevices devices;
  // --- cameras (Aravis, section `cameras:`): appended to devices.cameras here ---
#if SL_HAVE_ARAVIS
  appendAravisCameras(config, devices);
#else
  throw std::runtime_error(config.source_path + ": sensor 'hardware' needs the Aravis cameras, "
                           "which this build lacks (configure with libaravis-dev installed)");
#endif

  if (devices.cameras.empty())
    throw std::runtime_error(config.source_path +
                             ": sensor 'hardware' has no cameras (this build has no camera "
                             "driver configured)");

  const drivers::LightCrafter4500Config& p = config.hardware.projector;
#if SL_HAVE_HIDAPI
  try {
    devices.projector = std::make_shared<drivers::LightCrafter4500Projector>(
        p, [p] { return drivers::openHidapiTransport(p.vendor_id, p.product_id, p.serial); },
        [id = p.id](const std::string& note) { logWarning("projector '" + id + "': " + note); });
  } catch (const std::exception& e) {
    throw std::runtime_error("projector '" + p.id + "': " + e.what());
  }
#else
  throw std::runtime_error("projector '" + p.id + "': this build has no USB HID transport "
                           "(configure with libhidapi-dev installed)");
#endif

  if (config.hardware.trigger == HardwareConfig::Trigger::kVersavis) {
    return composeVersavis(config, std::move(devices.cameras), std::move(devices.projector),
                           openVersavis(config));
  } else {
    // The projector triggers the cameras: camera 0's stamps give the sequence
    // starts; the projector tells their length and frame period.
    auto source =
        std::make_shared<drivers::CameraStampTriggerSource>(config.hardware.camera_stamps);
    std::map<std::string, drivers::SequenceTapProjector::Timing> timing;
    auto sequences = p.sequences;
    for (const auto& s : drivers::builtinSequences(p.white_black_period_us)) sequences.push_back(s);
    for (const auto& s : sequences)
      timing[s.name] = {static_cast<int>(s.patterns.size()),
                        static_cast<pipeline::TimestampNs>(s.frame_period_us) * 1000};
    devices.cameras[0] = std::make_shared<drivers::StampTapCamera>(devices.cameras[0], source);
    devices.projector =
        std::make_shared<drivers::SequenceTapProjector>(devices.projector, source, timing);
    devices.trigger = source;
  }
  return devices;
}

}  // namespace

std::shared_ptr<drivers::VersavisTriggerSource> openVersavis(const DaemonConfig& config) {
  // Board log messages and the driver's notes into the daemon's log, by level.
  auto log = [](int level, const std::string& message) {
    if (level >= 3)
      logError(message);
    else if (level == 2)
      logWarning(message);
    else
      logInfo(message);
  };
  return std::make_shared<drivers::VersavisTriggerSource>(config.hardware.versavis, log);
}

EngineDevices composeVersavis(const DaemonConfig& config,
                              std::vector<std::shared_ptr<drivers::Camera>> cameras,
                              std::shared_ptr<drivers::Projector> projector,
                              std::shared_ptr<drivers::VersavisTriggerSource> board) {
  const auto& channels = config.hardware.versavis.camera_channels;
  EngineDevices devices;
  devices.projector =
      std::make_shared<drivers::VersavisStartTapProjector>(std::move(projector), board);
  devices.trigger = board;
  if (channels.empty()) {
    logWarning(config.source_path +
               ": trigger.versavis.camera_channels is empty: camera frames keep their own "
               "stamps and the board's clock offset to the host (about +100 ms after a board "
               "start) separates them from the projector trigger times");
    devices.cameras = std::move(cameras);
    return devices;
  }
  if (channels.size() != cameras.size())
    throw std::runtime_error(config.source_path + ": key 'trigger.versavis.camera_channels': " +
                             std::to_string(channels.size()) + " channels for " +
                             std::to_string(cameras.size()) + " cameras (one per camera)");
  for (std::size_t i = 0; i < cameras.size(); ++i)
    devices.cameras.push_back(
        std::make_shared<drivers::VersavisRestampCamera>(std::move(cameras[i]), board, i));
  return devices;
}

EngineDevices openDevices(const DaemonConfig& config, std::shared_ptr<void>& keep_alive) {
  switch (config.sensor) {
    case SensorKind::kSim: return openSimulated(config, keep_alive);
    case SensorKind::kHardware: return openHardware(config);
    case SensorKind::kFakeGige:
#if SL_HAVE_ARAVIS
      return openFakeGige(config, keep_alive);
#else
      throw std::runtime_error(config.source_path + ": sensor 'fake_gige' needs Aravis, which this "
                               "build lacks (configure with libaravis-dev installed)");
#endif
    case SensorKind::kReplay: return openReplay(config, keep_alive);
  }
  throw std::runtime_error(std::string("sensor '") + toString(config.sensor) +
                           "' is not supported by this build");
}

}  // namespace sl::daemon
