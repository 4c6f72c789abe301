#include "sl/pipeline/scan_processor.h"

#include <algorithm>
#include <atomic>
#include <stdexcept>
#include <string>

namespace sl::pipeline {

namespace {

// Buffers kept for reuse per kind: enough for a result in flight to each
// consumer (publishers, queues) while the next scan is processed; beyond
// that, fresh buffers are made and dropped by their last holder.
constexpr std::size_t kPoolSize = 4;

// True when `pool_ref` is the only owner. Nobody else can then gain a
// reference; the acquire fence orders the last holder's reads (its
// release-decrement) before our writes.
template <typename T>
bool isFree(const std::shared_ptr<T>& pool_ref) {
  if (pool_ref.use_count() != 1) return false;
  std::atomic_thread_fence(std::memory_order_acquire);
  return true;
}

}  // namespace

ScanProcessor::ScanProcessor(int threads)
    : workers_(threads), bands_(workers_.threads()), tallies_(workers_.threads()) {}

std::shared_ptr<ProjectorMaps> ScanProcessor::freeMaps(Direction direction) {
  for (MapsSlot& slot : maps_pool_) {
    if (slot.direction == direction && isFree(slot.maps)) return slot.maps;
  }
  // Codec::prepare() NaNs the unencoded map only when it allocates it: a
  // buffer last filled for another direction is replaced, not reused.
  for (MapsSlot& slot : maps_pool_) {
    if (isFree(slot.maps)) {
      slot = MapsSlot{std::make_shared<ProjectorMaps>(), direction};
      return slot.maps;
    }
  }
  auto maps = std::make_shared<ProjectorMaps>();
  if (maps_pool_.size() < kPoolSize) maps_pool_.push_back(MapsSlot{maps, direction});
  return maps;
}

std::shared_ptr<PointCloud> ScanProcessor::freeCloud() {
  for (const auto& cloud : cloud_pool_) {
    if (isFree(cloud)) return cloud;
  }
  auto cloud = std::make_shared<PointCloud>();
  if (cloud_pool_.size() < kPoolSize) cloud_pool_.push_back(cloud);
  return cloud;
}

// The maps the triangulator reads: without the one the pattern does not
// encode (all NaN) where that changes nothing but the memory read, since
// Use::kBest falls back to the other map per pixel anyway.
ProjectorMaps triangulatorView(const ProjectorMaps& maps, Direction direction,
                               const Triangulator& triangulator) {
  ProjectorMaps view;
  view.up = maps.up;
  view.vp = maps.vp;
  view.offset = maps.offset;
  if (triangulator.options().use == TriangulatorOptions::Use::kBest) {
    if (direction == Direction::kHorizontal) view.vp = cv::Mat();
    if (direction == Direction::kVertical) view.up = cv::Mat();
  }
  return view;
}

ScanOutput ScanProcessor::process(const Codec& codec, const Triangulator& triangulator,
                                  const CameraImages& images, TimestampNs stamp_ns,
                                  const std::string& frame_id, Keep keep, DecodeTally* tally) {
  const std::vector<cv::Mat>& frames = images.frames;
  const bool with_residual = tally != nullptr && hasConsistencyTest(codec.spec());
  if (tally != nullptr) std::fill(tallies_.begin(), tallies_.end(), DecodeTally{});
  auto mergeTallies = [&] {
    if (tally == nullptr) return;
    *tally = DecodeTally{};
    for (const DecodeTally& t : tallies_) tally->add(t);
  };
  const int bit_depth = images.bit_depth;
  const Direction direction = codec.spec().direction;
  std::shared_ptr<PointCloud> cloud = freeCloud();
  if (keep == Keep::kCloud) {
    // Checked once here rather than by the first block on some thread (each
    // block checks again).
    codec.checkFrames(frames, bit_depth);
    triangulator.prepareCloud(frame_id, stamp_ns, *cloud);
    if (frames.front().size() != cv::Size(cloud->width, cloud->height)) {
      throw std::invalid_argument("Triangulator: frames of " + std::to_string(frames.front().cols) +
                                  "x" + std::to_string(frames.front().rows) +
                                  " do not fit the camera size " + std::to_string(cloud->width) +
                                  "x" + std::to_string(cloud->height));
    }
    workers_.run(frames.front().rows, kBlockRows, [&](int begin, int end, int thread) {
      ProjectorMaps& band = bands_[thread];
      codec.decodeBand(frames, bit_depth, begin, end, band);
      if (tally != nullptr) tallies_[thread].addRows(band, 0, end - begin, with_residual, begin);
      triangulator.triangulateBand(triangulatorView(band, direction, triangulator), begin, end,
                                   *cloud);
    });
    mergeTallies();
    return ScanOutput{nullptr, std::move(cloud)};
  }
  std::shared_ptr<ProjectorMaps> maps = freeMaps(direction);
  codec.prepare(frames, bit_depth, *maps);
  maps->camera_id = images.camera_id;
  maps->stamp_ns = stamp_ns;
  const ProjectorMaps view = triangulatorView(*maps, direction, triangulator);
  triangulator.prepare(view, *cloud);
  cloud->frame_id = frame_id;
  cloud->stamp_ns = stamp_ns;
  workers_.run(frames.front().rows, kBlockRows, [&](int begin, int end, int thread) {
    codec.decodeRows(frames, bit_depth, begin, end, *maps);
    if (tally != nullptr) tallies_[thread].addRows(*maps, begin, end, with_residual, begin);
    triangulator.triangulateRows(view, begin, end, *cloud);
  });
  mergeTallies();
  return ScanOutput{std::move(maps), std::move(cloud)};
}

std::shared_ptr<const ProjectorMaps> ScanProcessor::decode(const Codec& codec,
                                                           const CameraImages& images,
                                                           TimestampNs stamp_ns) {
  std::shared_ptr<ProjectorMaps> maps = freeMaps(codec.spec().direction);
  const std::vector<cv::Mat>& frames = images.frames;
  const int bit_depth = images.bit_depth;
  codec.prepare(frames, bit_depth, *maps);
  maps->camera_id = images.camera_id;
  maps->stamp_ns = stamp_ns;
  workers_.run(frames.front().rows, kBlockRows, [&](int begin, int end, int) {
    codec.decodeRows(frames, bit_depth, begin, end, *maps);
  });
  return maps;
}

}  // namespace sl::pipeline
