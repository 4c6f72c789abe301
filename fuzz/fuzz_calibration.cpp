// The calibration importers: the project's YAML, SLStudio's calibration.xml
// (OpenCV FileStorage XML / YAML) and sl_sensor's camera + projector pair.
// The first byte picks the reader and extension; the rest is the file.
// Every problem must be a ConfigError naming the file.
#include <cstdint>
#include <string>

#include "fuzz_support.h"
#include "sl/files/calibration_io.h"
#include "sl/daemon/config.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const int mode = data[0] % 4;
  static const char* kNames[] = {"calibration.yaml", "calibration.xml", "camera.xml", "projector.xml"};
  const std::string path = sl::fuzz::writeScratch(kNames[mode], data + 1, size - 1);
  try {
    if (mode < 2) {
      sl::files::loadCalibration(path);
    } else {
      // The fuzzed file as one of the pair, the other the valid sl_sensor
      // file of the seed corpus.
      const std::string other = std::string(SL_FUZZ_DIR) +
                                (mode == 2 ? "/data/sl_sensor_projector.xml"
                                           : "/data/sl_sensor_camera.xml");
      if (mode == 2)
        sl::files::loadSlSensorCalibration(path, other);
      else
        sl::files::loadSlSensorCalibration(other, path);
    }
  } catch (const sl::files::ConfigError&) {
  }
  return 0;
}
