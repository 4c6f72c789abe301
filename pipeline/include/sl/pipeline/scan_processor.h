// Decode + triangulate of one camera's images of a scan, split over the rows
// of the image on a RowWorkers pool and with buffers recycled from earlier
// scans: what the daemon's processing stage runs per camera.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/decode_health.h"
#include "sl/pipeline/row_workers.h"
#include "sl/pipeline/triangulator.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

struct ScanOutput {
  std::shared_ptr<const ProjectorMaps> maps;  // null when not kept (ScanProcessor::Keep)
  std::shared_ptr<const PointCloud> cloud;
};

// Thread-compatible: one processing thread owns it (its worker threads are
// its own). Results are shared, immutable for their holders: a buffer is
// refilled only after every ScanOutput pointer to it has been released, so
// callers that keep results keep them intact (they just cost fresh buffers).
class ScanProcessor {
 public:
  // threads: as RowWorkers (caller included).
  explicit ScanProcessor(int threads = RowWorkers::defaultThreads());

  int threads() const { return workers_.threads(); }
  // Its pool, for other per-scan work of the same thread between process()
  // calls (e.g. MotionCompensator::compensate).
  RowWorkers& workers() { return workers_; }

  // What process() returns besides the cloud.
  enum class Keep {
    kMapsAndCloud,
    // The maps of a block live only in the decoding thread's band buffer
    // until the block is triangulated: 13 bytes per pixel that are never
    // written to memory (1440 x 1080: 20 MB per scan, as much memory traffic
    // as the cloud's 25 MB). For callers that do not use the maps.
    kCloud,
  };

  // Decodes images.frames with `codec` and triangulates with `triangulator`,
  // blocks of rows at a time, each block triangulated right after it is
  // decoded (its maps rows still in cache). maps.camera_id = images.camera_id,
  // cloud.frame_id = frame_id, both stamped stamp_ns. Same results as
  // codec.decode() then triangulator.triangulate(), with either `keep`.
  // Throws as those do (std::invalid_argument on frames or a calibration
  // that do not fit). With a `tally`, it is overwritten with the counts of
  // the decoded maps (status of every pixel, residual of the modulated ones
  // when the code has a consistency test), gathered block by block while
  // the maps are in cache: judgeDecodeTally() makes the scan's decode health.
  ScanOutput process(const Codec& codec, const Triangulator& triangulator,
                     const CameraImages& images, TimestampNs stamp_ns, const std::string& frame_id,
                     Keep keep = Keep::kMapsAndCloud, DecodeTally* tally = nullptr);

  // Decoding only (maps as in process()).
  std::shared_ptr<const ProjectorMaps> decode(const Codec& codec, const CameraImages& images,
                                              TimestampNs stamp_ns);

  // Rows per block handed to a thread: decoded maps of a block stay in L2
  // until the block is triangulated.
  static constexpr int kBlockRows = 16;

 private:
  // A free (unshared) maps buffer last filled for `direction`, or a new one.
  std::shared_ptr<ProjectorMaps> freeMaps(Direction direction);
  std::shared_ptr<PointCloud> freeCloud();

  RowWorkers workers_;
  // Keep::kCloud: per worker thread, the maps of its current block of rows.
  std::vector<ProjectorMaps> bands_;
  std::vector<DecodeTally> tallies_;  // per worker thread, for process(..., tally)
  // Recycled buffers; free when this pool holds the only reference.
  struct MapsSlot {
    std::shared_ptr<ProjectorMaps> maps;
    Direction direction;  // of the codec that last filled it (its unencoded map is NaN)
  };
  std::vector<MapsSlot> maps_pool_;
  std::vector<std::shared_ptr<PointCloud>> cloud_pool_;
};

}  // namespace sl::pipeline
