// The replay sensor: plays a recording (sl/drivers/recording.h: a recording
// folder or an MCAP file of the daemon's image sets) back through
// the Camera / Projector / TriggerSource interfaces, so the daemon processes
// recorded image sets exactly as it processed them live.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "sl/drivers/camera.h"
#include "sl/drivers/projector.h"
#include "sl/drivers/trigger_source.h"

namespace sl::drivers {

struct ReplayConfig {
  std::string dir;   // the recording: a folder, or an MCAP file with image sets (recording.h)
  bool loop = true;  // wrap around at the end of the recording (else stop there)
  // Decoded sets kept in memory (least recently used dropped first), so that
  // a looping replay decodes each image once instead of on every pass. At
  // least the set being played is kept, whatever the bound.
  std::size_t cache_bytes = std::size_t{256} << 20;
};

// Thread-safe, like the simulated sensor: one thread per camera grab(),
// one for triggers, start/stop from another.
//
// Projector::start(count) plays `count` sets (0 = until stop) of the selected
// pattern, in recording order. Sequence k is re-stamped to start at
// t0 + k * period (t0 = start + 20 ms, period = the recording's trigger
// interval for that pattern); each frame keeps its recorded offset from its
// trigger, so grouping by trigger time sees the same timing as live. Images
// are loaded from the recording, a set at a time, when first grabbed, and decoded sets
// stay in a cache bounded by ReplayConfig::cache_bytes.
class ReplaySensor {
 public:
  // Reads the recording's metadata (not its images). Throws
  // std::runtime_error naming the folder or file on a bad recording.
  static std::shared_ptr<ReplaySensor> open(const ReplayConfig& config);
  virtual ~ReplaySensor() = default;

  virtual std::vector<std::shared_ptr<Camera>> cameras() = 0;  // in recording order
  virtual std::shared_ptr<Projector> projector() = 0;  // one sequence per recorded pattern
  virtual std::shared_ptr<TriggerSource> triggerSource() = 0;
  virtual std::size_t setCount() const = 0;
};

}  // namespace sl::drivers
