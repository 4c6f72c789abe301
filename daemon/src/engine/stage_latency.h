// Where a cloud's latency goes inside the daemon, per scan: from the trigger
// of the sequence's last pattern to the end of its publication, split into
// the wait for the images and their grouping, processing (motion
// compensation, decode, triangulation) and publishing (the cloud's write and
// the scan's other topics). A window of the last scans gives the status its
// medians and maximum.
#pragma once

#include <array>
#include <cstddef>
#include <mutex>

#include "sl/pipeline/types.h"

namespace sl::daemon {

// One scan's stages, in milliseconds.
struct StageTimes {
  double wait_ms = 0;        // last pattern's trigger -> processing starts
  double processing_ms = 0;  // processing of the image set
  double publish_ms = 0;     // processing done -> the scan's topics written
  double totalMs() const { return wait_ms + processing_ms + publish_ms; }
};

struct StageSummary {
  std::size_t scans = 0;  // in the window (0: no figures yet)
  StageTimes median;      // of each stage on its own
  double total_median_ms = 0;
  double total_max_ms = 0;
};

// The latest exposure of `set` (its sequence's last pattern), system clock.
pipeline::TimestampNs lastExposureNs(const pipeline::ImageSet& set);

// One scan's stages from the sequence's last exposure and the processing's
// start and end to the end of its publication (system clock, ns); a stage
// that comes out negative (the clock was set back) counts as 0.
StageTimes stageTimes(pipeline::TimestampNs exposed_ns, pipeline::TimestampNs processing_ns,
                      pipeline::TimestampNs processed_ns, pipeline::TimestampNs published_ns);

// Thread-safe: the output thread adds, status() summarises.
class StageLatency {
 public:
  static constexpr std::size_t kWindow = 64;  // scans

  void add(const StageTimes& scan);
  StageSummary summary() const;
  void clear();

 private:
  mutable std::mutex mutex_;
  std::array<StageTimes, kWindow> ring_{};  // guarded by mutex_
  std::size_t next_ = 0;                    // guarded by mutex_
  std::size_t count_ = 0;                   // guarded by mutex_
};

}  // namespace sl::daemon
