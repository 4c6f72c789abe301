// Fresh memory for the stage threads before the first scan
// (runtime.prefault_memory; the points writer's history always). On a
// machine whose free memory is handed back to the hypervisor (free page
// reporting), the first touch of a page costs
// far more than on bare metal (docs/measurements.md, "First touches on
// this VM").
// Without this, the first second after START paid for every image, cloud
// and serialized sample the stages allocate for the first time (measured at
// 30 scans/s: 31,500 page faults in the camera thread and 18,200 in each of
// the processing and output threads, ~270 MB, all within that second). Each stage thread touches
// and frees, at its start, what its steady state recycles; sl::dds::retainLargeSampleMemory's
// allocator settings keep that memory with the thread's malloc arena.
#pragma once

#include <cstddef>

#include "sl/daemon/config.h"

namespace sl::daemon {

struct PrefaultPlan {
  std::size_t frame_bytes = 0;     // one camera image (the largest camera)
  std::size_t frames = 0;          // images per camera thread
  std::size_t cloud_bytes = 0;     // one full-resolution cloud (16 bytes a point), largest camera
  std::size_t process_clouds = 0;  // clouds of the processing thread
  // The output thread's messages and serialized copies (the writers' histories).
  std::size_t output_block_bytes = 0;
  std::size_t output_blocks = 0;

  std::size_t totalBytes(std::size_t cameras) const {
    return cameras * frames * frame_bytes + process_clouds * cloud_bytes +
           output_blocks * output_block_bytes;
  }
};

// Sizes from the cameras' calibrations and image depth, the longest
// pattern, runtime.queue_depth, the input queue's capacity and the points
// topic's layout and QoS. With runtime.prefault_memory off, only the points
// writer's history (reliable points): history depth + 1 serialized clouds
// for the output thread, or, when the writer keeps the processing thread's
// clouds themselves (clouds_kept_by_writer: ResultContents::keeps_clouds),
// history depth + 2 clouds for the processing thread (those the history
// holds, the one in processing and the one being written).
PrefaultPlan prefaultPlanOf(const DaemonConfig& config, std::size_t input_queue_capacity,
                            bool clouds_kept_by_writer = false);

// Touches `count` blocks of `block_bytes` in the calling thread's heap and
// frees them (see above). No-op for a zero count or block.
void prefaultThreadHeap(std::size_t block_bytes, std::size_t count);

}  // namespace sl::daemon
