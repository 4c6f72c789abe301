#include "engine/memory_prefault.h"

#include "sl/dds/cloud_layout.h"
#include "sl/dds/dds.h"

#include <algorithm>

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::dds::maxPackedBytes;

namespace {

std::size_t bytesPerPixel(const DaemonConfig& config) {
  if (config.sensor == SensorKind::kSim) return config.sim.bit_depth > 8 ? 2 : 1;
  for (const drivers::AravisCameraConfig& camera : config.aravis.cameras)
    if (camera.pixel_format != "Mono8") return 2;
  return config.aravis.cameras.empty() ? 2 : 1;  // replay: 8- or 16-bit images
}

}  // namespace

PrefaultPlan prefaultPlanOf(const DaemonConfig& config, std::size_t input_queue_capacity,
                            bool clouds_kept_by_writer) {
  PrefaultPlan plan;
  std::size_t pixels = static_cast<std::size_t>(config.calibration.camera.width) *
                       static_cast<std::size_t>(config.calibration.camera.height);
  int width = config.calibration.camera.width;
  int height = config.calibration.camera.height;
  for (const auto& [id, calibration] : config.extra_calibrations) {
    pixels = std::max(pixels, static_cast<std::size_t>(calibration.camera.width) *
                                  static_cast<std::size_t>(calibration.camera.height));
    width = std::max(width, calibration.camera.width);
    height = std::max(height, calibration.camera.height);
  }
  // The points writer's history, whatever runtime.prefault_memory says: a
  // reliable keep-last writer keeps the serialized clouds a reader has not
  // acknowledged, all `depth` of them while a reader is stopped, besides
  // the one being written. Left to grow on demand, the first reader that
  // stopped delayed every other reader's next clouds (each write faulting
  // in a fresh 25 MB; docs/measurements.md, "Findings").
  const std::size_t history = static_cast<std::size_t>(config.dds.points_qos.depth);
  if (config.dds.points_qos.reliable && clouds_kept_by_writer) {
    // The history holds the processing thread's clouds (zero-copy points):
    // with a reader stopped, the processor's pool is all held and every
    // scan takes a fresh cloud: processing must never wait for fresh
    // pages while a reader is stopped.
    plan.cloud_bytes = pixels * 16;
    plan.process_clouds = history + 2;
  } else if (config.dds.points_qos.reliable) {
    // The published cloud's points, and a page for the message's header and
    // the serialized sample's own.
    plan.output_block_bytes = maxPackedBytes(width, height, config.dds.points_layout) + 4096;
    plan.output_blocks = history + 1;
  }
  if (!config.runtime.prefault_memory) return plan;
  std::size_t longest = 1;
  for (const pipeline::PatternSpec& p : config.patterns)
    longest = std::max(longest, static_cast<std::size_t>(p.frameCount()));
  const std::size_t depth = static_cast<std::size_t>(config.runtime.queue_depth);
  plan.frame_bytes = pixels * bytesPerPixel(config);
  // The sets waiting and in processing, and a full input queue.
  plan.frames = longest * (depth + 2) + input_queue_capacity;
  plan.cloud_bytes = pixels * 16;
  // Clouds waiting for output, in processing, and the decoder's maps; the
  // output thread's messages and serialized copies (writer history), at
  // least the points writer's history above.
  // Measured: with depth + 2 each, a thread still faulted in one more cloud.
  plan.process_clouds = std::max(plan.process_clouds, depth + 3);
  plan.output_block_bytes = std::max(plan.output_block_bytes, plan.cloud_bytes);
  plan.output_blocks = std::max(plan.output_blocks, depth + 3);
  return plan;
}

void prefaultThreadHeap(std::size_t block_bytes, std::size_t count) {
  dds::prefaultHeap(block_bytes, count);
}

}  // namespace sl::daemon
