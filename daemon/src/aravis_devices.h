// Device factory part for the Aravis cameras; called from devices.cpp.
#pragma once

#include <memory>

#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"

namespace sl::daemon {

// Opens config.aravis.cameras (in order) and appends them to devices.cameras;
// logs what each camera's configuration skipped. Throws std::runtime_error
// naming the camera.
void appendAravisCameras(const DaemonConfig& config, EngineDevices& devices);

// sensor: fake_gige -- the simulated sensor's projector and trigger source,
// an in-process fake GigE Vision camera fed with the simulated camera's
// frames (one software trigger per frame, device timestamp = the simulated
// exposure time), and the configured AravisCamera opening it over GVCP/GVSP.
// `keep_alive` owns the simulator, the fake camera and the feeder thread.
EngineDevices openFakeGige(const DaemonConfig& config, std::shared_ptr<void>& keep_alive);

}  // namespace sl::daemon
