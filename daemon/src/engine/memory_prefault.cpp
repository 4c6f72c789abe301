#include "engine/memory_prefault.h"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <vector>

namespace sl::daemon {

namespace {

// retainLargeSampleMemory's mmap threshold: larger blocks are mapped for
// each allocation and unmapped when freed, so touching them ahead is useless.
constexpr std::size_t kLargestHeapBlock = std::size_t{32} << 20;

std::size_t bytesPerPixel(const DaemonConfig& config) {
  if (config.sensor == SensorKind::kSim) return config.sim.bit_depth > 8 ? 2 : 1;
  for (const drivers::AravisCameraConfig& camera : config.aravis.cameras)
    if (camera.pixel_format != "Mono8") return 2;
  return config.aravis.cameras.empty() ? 2 : 1;  // replay: 8- or 16-bit images
}

}  // namespace

PrefaultPlan prefaultPlanOf(const DaemonConfig& config, std::size_t input_queue_capacity) {
  PrefaultPlan plan;
  if (!config.runtime.prefault_memory) return plan;
  std::size_t pixels = static_cast<std::size_t>(config.calibration.camera.width) *
                       static_cast<std::size_t>(config.calibration.camera.height);
  for (const auto& [id, calibration] : config.extra_calibrations)
    pixels = std::max(pixels, static_cast<std::size_t>(calibration.camera.width) *
                                  static_cast<std::size_t>(calibration.camera.height));
  std::size_t longest = 1;
  for (const pipeline::PatternSpec& p : config.patterns)
    longest = std::max(longest, static_cast<std::size_t>(p.frameCount()));
  const std::size_t depth = static_cast<std::size_t>(config.runtime.queue_depth);
  plan.frame_bytes = pixels * bytesPerPixel(config);
  // The sets waiting and in processing, and a full input queue.
  plan.frames = longest * (depth + 2) + input_queue_capacity;
  plan.cloud_bytes = pixels * 16;
  // Clouds waiting for output, in processing, and the decoder's maps; the
  // output thread's messages and serialized copies (writer history).
  // Measured: with depth + 2 each, a thread still faulted in one more cloud.
  plan.process_clouds = depth + 3;
  plan.output_clouds = depth + 3;
  return plan;
}

void prefaultThreadHeap(std::size_t block_bytes, std::size_t count) {
  if (block_bytes == 0 || count == 0 || block_bytes >= kLargestHeapBlock) return;
  const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  std::vector<unsigned char*> blocks;
  blocks.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    auto* block = static_cast<unsigned char*>(std::malloc(block_bytes));
    if (!block) break;  // what was touched still helps
    for (std::size_t offset = 0; offset < block_bytes; offset += page)
      static_cast<volatile unsigned char*>(block)[offset] = 0;
    blocks.push_back(block);
  }
  for (auto it = blocks.rbegin(); it != blocks.rend(); ++it) std::free(*it);
}

}  // namespace sl::daemon
