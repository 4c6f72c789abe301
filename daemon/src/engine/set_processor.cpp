#include "engine/set_processor.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include <opencv2/core.hpp>

#include "sl/pipeline/intensity_transfer.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::dds::PointQuality;

ProcessingConfig processingConfigOf(const DaemonConfig& config, const std::vector<std::string>& camera_ids,
                                    double cloud_unit_mm, bool keep_maps) {
  ProcessingConfig p;
  p.cloud_unit_mm = cloud_unit_mm;
  p.patterns = config.patterns;
  p.decoder = config.decoder;
  p.triangulator = config.triangulator;
  for (std::size_t i = 0; i < camera_ids.size(); ++i) {
    if (i == 0) {
      p.calibrations.emplace(camera_ids[i], config.calibration);
    } else if (const auto c = config.extra_calibrations.find(camera_ids[i]);
               c != config.extra_calibrations.end()) {
      p.calibrations.emplace(camera_ids[i], c->second);
    }
  }
  p.intensity_camera = config.pattern_intensity_camera;
  p.motion_enabled = config.motion.enabled;
  p.motion = config.motion.options;
  p.keep_maps = keep_maps;
  p.camera_noise = config.camera_noise;
  return p;
}

namespace {

// The cameras' models (motion compensation works in undistorted coordinates).
std::map<std::string, pipeline::PinholeModel> cameraModels(const ProcessingConfig& config) {
  std::map<std::string, pipeline::PinholeModel> models;
  for (const auto& [id, calibration] : config.calibrations) models.emplace(id, calibration.camera);
  return models;
}

// `config` with the calibrations and the depth limits in the clouds' unit.
// The maps are kept for the caller or for the depth sigma.
pipeline::ScanProcessor::Keep keepOf(const ProcessingConfig& config) {
  return config.keep_maps || config.depth_sigma ? pipeline::ScanProcessor::Keep::kMapsAndCloud
                                                : pipeline::ScanProcessor::Keep::kCloud;
}

ProcessingConfig inCloudUnit(ProcessingConfig config) {
  if (!(config.cloud_unit_mm > 0 && std::isfinite(config.cloud_unit_mm)))
    throw std::invalid_argument("cloud unit must be a positive number of mm");
  if (config.depth_sigma && !config.camera_noise)
    throw std::invalid_argument("the depth sigma (dds.points_confidence) needs camera_noise");
  if (config.normals && config.normal_step < 1)
    throw std::invalid_argument("normal step must be at least 1 px");
  if (config.cloud_unit_mm == 1.0) return config;
  const double per_mm = 1.0 / config.cloud_unit_mm;
  for (auto& [id, calibration] : config.calibrations) calibration = pipeline::inUnits(calibration, per_mm);
  config.triangulator.min_depth_mm = static_cast<float>(config.triangulator.min_depth_mm * per_mm);
  config.triangulator.max_depth_mm = static_cast<float>(config.triangulator.max_depth_mm * per_mm);
  return config;
}

}  // namespace

SetProcessor::SetProcessor(const ProcessingConfig& config)
    : loaded_(config), config_(inCloudUnit(config)), stages_(build(config_)),
      motion_(config.motion, cameraModels(config)) {
  warmUp();
}

// The first scan after start-up allocates the cloud and the row workers'
// band buffers, and each fresh page costs a fault (on this project's 2-core
// VM: docs/measurements.md). Decoding black frames (every pixel
// invalid, but every buffer written) moves that cost to start-up; the
// cloud then waits in the processor's pool for the first scan.
void SetProcessor::warmUp() {
  if (stages_.decoders.empty()) return;
  const pipeline::Codec& codec = stages_.decoders.begin()->second.codec();
  for (const auto& [camera_id, triangulator] : stages_.triangulators) {
    const pipeline::PinholeModel& camera = config_.calibrations.at(camera_id).camera;
    pipeline::CameraImages black;
    black.camera_id = camera_id;
    black.bit_depth = 8;
    const cv::Mat zeros = cv::Mat::zeros(camera.height, camera.width, CV_8UC1);
    black.frames.assign(static_cast<std::size_t>(codec.frameCount()), zeros);
    black.stamps_ns.assign(black.frames.size(), 0);
    try {
      processor_.process(codec, triangulator, black, 0, camera_id, keepOf(config_));
    } catch (const std::exception&) {
      // A pattern that cannot decode at this size fails the same way on its
      // first scan, where the error is reported.
    }
  }
}

SetProcessor::Stages SetProcessor::build(const ProcessingConfig& config) {
  Stages stages;
  for (const auto& p : config.patterns) stages.decoders.emplace(p.name, pipeline::Decoder(p, config.decoder));
  for (const auto& [id, calibration] : config.calibrations)
    stages.triangulators.emplace(id, pipeline::Triangulator(calibration, config.triangulator));
  return stages;
}

std::string SetProcessor::reconfigure(const ProcessingConfig& config) {
  try {
    ProcessingConfig scaled = inCloudUnit(config);
    Stages rebuilt = build(scaled);
    pipeline::MotionCompensator motion(config.motion, cameraModels(config));
    stages_ = std::move(rebuilt);
    motion_ = std::move(motion);
    config_ = std::move(scaled);
    loaded_ = config;
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

std::string SetProcessor::applyRuntimeSettings(const DaemonConfig& settings) {
  ProcessingConfig next = loaded_;
  next.decoder = settings.decoder;
  next.triangulator = settings.triangulator;
  next.motion = settings.motion.options;
  next.motion_enabled = settings.motion.enabled;
  return reconfigure(next);
}

void PendingSettings::post(const DaemonConfig& settings) {
  std::lock_guard lock(mutex_);
  settings_ = settings;
  pending_ = true;
}

std::optional<DaemonConfig> PendingSettings::take() {
  if (!pending_) return std::nullopt;
  std::lock_guard lock(mutex_);
  pending_ = false;
  return std::exchange(settings_, std::nullopt);
}

SetOutcome SetProcessor::process(const pipeline::ImageSet& input, const std::vector<std::string>& cameras,
                                 bool motion_compensation) {
  SetOutcome out;
  // Motion compensation aligns every frame with the reference frame of its
  // sequence; the cloud is then stamped with the reference frame's time.
  // Only the cameras this set is processed with are compensated: those
  // that triangulate it and the pattern's intensity camera (the images of a
  // camera the pattern does not use are not read).
  std::shared_ptr<const pipeline::ImageSet> compensated;
  if (motion_compensation) {
    try {
      pipeline::ImageSet used = input;
      const auto intensity = config_.intensity_camera.find(input.pattern_name);
      std::erase_if(used.cameras, [&](const pipeline::CameraImages& c) {
        return std::find(cameras.begin(), cameras.end(), c.camera_id) == cameras.end() &&
               (intensity == config_.intensity_camera.end() || intensity->second != c.camera_id);
      });
      pipeline::MotionEstimate estimate;
      // None used: the whole set, so that the errors below name the missing camera.
      compensated = motion_.compensate(used.cameras.empty() ? input : used, &estimate,
                                       &processor_.workers());
      if (!estimate.all_within_limit)
        out.warning = "motion compensation: a shift beyond max_shift_px was ignored";
      else if (estimate.frames_corrected > 0)
        out.warning = "motion compensation: " + std::to_string(estimate.frames_corrected) +
                      " frame(s) whose shift disagreed with the sequence's motion (a false "
                      "correlation peak) registered again near the motion's prediction";
    } catch (const std::exception& e) {
      out.error = std::string("motion compensation: ") + e.what();
      return out;
    }
  }
  const pipeline::ImageSet& set = compensated ? *compensated : input;
  try {
    const auto decoder = stages_.decoders.find(set.pattern_name);
    if (decoder == stages_.decoders.end())
      throw std::runtime_error("no decoder for pattern '" + set.pattern_name + "'");
    for (const std::string& camera_id : cameras) {
      const auto images = std::find_if(set.cameras.begin(), set.cameras.end(),
                                       [&](const auto& c) { return c.camera_id == camera_id; });
      if (images == set.cameras.end())
        throw std::runtime_error("no images of camera '" + camera_id + "' in the set");
      const auto triangulator = stages_.triangulators.find(camera_id);
      if (triangulator == stages_.triangulators.end())
        throw std::runtime_error("no calibration of camera '" + camera_id + "'");
      const pipeline::Codec& codec = decoder->second.codec();
      pipeline::DecodeTally tally;
      auto [maps, cloud] = processor_.process(codec, triangulator->second, *images,
                                              set.trigger_stamp_ns, camera_id, keepOf(config_), &tally);
      std::shared_ptr<const PointQuality> quality = pointQuality(codec.spec(), camera_id,
                                                                 images->bit_depth, maps.get(), *cloud);
      if (!config_.keep_maps) maps = nullptr;  // kept for the depth sigma only
      if (auto coloured = colouredCopy(set, camera_id, *cloud)) cloud = std::move(coloured);
      out.scans.push_back({camera_id, images->bit_depth, std::move(maps), std::move(cloud),
                           pipeline::judgeDecodeTally(codec.spec(), codec.options(), tally),
                           std::move(quality)});
    }
  } catch (const std::exception& e) {
    out.scans.clear();
    out.error = "processing sequence " + std::to_string(set.sequence_id) + ": " + e.what();
  }
  return out;
}

// The per-point quality of `cloud` (triangulated by `camera_id` from `maps`
// of `spec`, images of `bit_depth`); nullptr when none is asked for. The
// processor's row workers take blocks of rows, each with a copy of its rows
// and `normal_step` more on either side, so that every value is the one the
// whole-image functions give (their results depend on a pixel's row and
// column neighbourhood only).
std::shared_ptr<const PointQuality> SetProcessor::pointQuality(const pipeline::PatternSpec& spec,
                                                               const std::string& camera_id, int bit_depth,
                                                               const pipeline::ProjectorMaps* maps,
                                                               const pipeline::PointCloud& cloud) {
  if (!config_.depth_sigma && !config_.normals) return nullptr;
  if (config_.depth_sigma && !maps) throw std::logic_error("depth sigma: the maps were not kept");
  const int rows = cloud.height, cols = cloud.width;
  auto quality = std::make_shared<PointQuality>();
  if (config_.depth_sigma) quality->depth_sigma.create(rows, cols, CV_32FC1);
  if (config_.normals) quality->normals.create(rows, cols, CV_32FC3);
  pipeline::CameraNoise noise = config_.camera_noise.value_or(pipeline::CameraNoise{});
  noise.bit_depth = bit_depth;
  const pipeline::CameraProjectorCalibration& calibration = config_.calibrations.at(camera_id);
  const int halo = config_.normals ? config_.normal_step : 0;
  const float max_jump = static_cast<float>(config_.normal_max_jump_mm / config_.cloud_unit_mm);
  constexpr int kBlockRows = 128;
  try {
    processor_.workers().run(rows, kBlockRows, [&](int begin, int end, int) {
      const int lo = std::max(0, begin - halo), hi = std::min(rows, end + halo);
      pipeline::PointCloud band;
      band.width = cols;
      band.height = hi - lo;
      band.points.assign(cloud.points.begin() + static_cast<std::ptrdiff_t>(lo) * cols,
                         cloud.points.begin() + static_cast<std::ptrdiff_t>(hi) * cols);
      if (config_.depth_sigma) {
        auto rowsOf = [&](const cv::Mat& m) { return m.empty() ? cv::Mat() : m.rowRange(lo, hi); };
        pipeline::ProjectorMaps band_maps;
        band_maps.up = rowsOf(maps->up);
        band_maps.vp = rowsOf(maps->vp);
        band_maps.modulation = rowsOf(maps->modulation);
        band_maps.offset = rowsOf(maps->offset);
        band_maps.status = rowsOf(maps->status);
        pipeline::depthSigma(band_maps, band, calibration, spec, noise, config_.triangulator.use)
            .rowRange(begin - lo, end - lo)
            .copyTo(quality->depth_sigma.rowRange(begin, end));
      }
      if (config_.normals)
        pipeline::organizedNormals(band, config_.normal_step, max_jump)
            .rowRange(begin - lo, end - lo)
            .copyTo(quality->normals.rowRange(begin, end));
    });
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("per-point quality (dds.points_confidence / points_normals): ") +
                                e.what());
  }
  return quality;
}

// A copy of `cloud` (triangulated by `camera_id`) with the intensity seen by
// the pattern's intensity camera; nullptr when the pattern has none.
std::shared_ptr<const pipeline::PointCloud> SetProcessor::colouredCopy(
    const pipeline::ImageSet& set, const std::string& camera_id, const pipeline::PointCloud& cloud) const {
  const auto other = config_.intensity_camera.find(set.pattern_name);
  if (other == config_.intensity_camera.end() || other->second == camera_id) return nullptr;
  const auto images = std::find_if(set.cameras.begin(), set.cameras.end(),
                                   [&](const auto& c) { return c.camera_id == other->second; });
  if (images == set.cameras.end())
    throw std::runtime_error("no images of intensity camera '" + other->second + "' in the set");
  auto coloured = std::make_shared<pipeline::PointCloud>(cloud);
  pipeline::transferIntensity(*coloured, config_.calibrations.at(camera_id),
                              config_.calibrations.at(other->second), *images);
  return coloured;
}

}  // namespace sl::daemon
