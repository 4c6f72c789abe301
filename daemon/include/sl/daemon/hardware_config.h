// Configuration of the real sensor's projector and trigger source
// (`sensor: hardware`): plain driver structs, filled from YAML by
// daemon/src/hardware_config.cpp. The cameras (Aravis) have their own section.
#pragma once

#include "sl/drivers/camera_stamp_trigger.h"
#include "sl/drivers/lightcrafter4500.h"
#include "sl/drivers/versavis.h"

namespace sl::daemon {

struct HardwareConfig {
  drivers::LightCrafter4500Config projector;
  enum class Trigger {
    kVersavis,      // trigger times from the VersaVIS board (paper section 3.2)
    kCameraStamps,  // projector triggers the cameras: times from frame stamps
  };
  Trigger trigger = Trigger::kVersavis;
  drivers::VersavisConfig versavis;
  drivers::CameraStampTriggerConfig camera_stamps;
};

}  // namespace sl::daemon
