#include "sl/daemon/devices.h"

#include <stdexcept>

#include "sl/drivers/sim.h"

namespace sl::daemon {

EngineDevices openDevices(const DaemonConfig& config, std::shared_ptr<void>& keep_alive) {
  if (config.sensor != "sim")
    throw std::runtime_error("sensor '" + config.sensor + "' is not supported by this build");
  std::shared_ptr<drivers::SimulatedSensor> sim;
  try {
    sim = drivers::SimulatedSensor::create(config.sim);
  } catch (const std::exception& e) {
    throw std::runtime_error(config.source_path + ": simulated sensor: " + e.what());
  }
  keep_alive = sim;
  EngineDevices devices;
  devices.cameras.push_back(sim->camera());
  devices.projector = sim->projector();
  devices.trigger = sim->triggerSource();
  return devices;
}

}  // namespace sl::daemon
