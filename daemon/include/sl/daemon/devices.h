// Builds the devices named by the config: the one place that knows every
// driver (the simulated sensor now; Aravis / LightCrafter / VersaVIS later).
#pragma once

#include <memory>

#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"

namespace sl::daemon {

// Opens the devices; throws std::runtime_error naming the device on failure.
// `keep_alive` receives an owner that must outlive the devices (the simulated
// sensor's shared world).
EngineDevices openDevices(const DaemonConfig& config, std::shared_ptr<void>& keep_alive);

}  // namespace sl::daemon
