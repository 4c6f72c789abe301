// Builds the devices named by the config (`sensor:`): the one place that
// knows every driver family -- the simulated sensor, a replayed recording,
// Aravis cameras, the LightCrafter 4500, VersaVIS or camera-stamp trigger
// times. Families this build lacks (SL_WITH_ARAVIS, SL_WITH_HIDAPI off) are
// refused with an error naming the missing library.
#pragma once

#include <memory>

#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"
#include "sl/drivers/versavis.h"

namespace sl::daemon {

// Opens the devices; throws std::runtime_error naming the device on failure.
// `keep_alive` receives an owner that must outlive the devices (the simulated
// sensor's shared world, a replay, the fake GigE camera's feeder).
EngineDevices openDevices(const DaemonConfig& config, std::shared_ptr<void>& keep_alive);

// The VersaVIS part of `sensor: hardware` (also used by the tests with fake
// devices): the trigger source from config.hardware.versavis, whose board
// log messages and notes go to the daemon's log.
std::shared_ptr<drivers::VersavisTriggerSource> openVersavis(const DaemonConfig& config);
// Cameras (in config order), projector and board composed: each camera is
// wrapped in a VersavisRestampCamera for its trigger.versavis.camera_channels
// entry, so frames carry the board's camera trigger times and group with its
// projector trigger times on one clock. Throws std::runtime_error naming the
// key when the channel count does not match the cameras.
EngineDevices composeVersavis(const DaemonConfig& config,
                              std::vector<std::shared_ptr<drivers::Camera>> cameras,
                              std::shared_ptr<drivers::Projector> projector,
                              std::shared_ptr<drivers::VersavisTriggerSource> board);

}  // namespace sl::daemon
