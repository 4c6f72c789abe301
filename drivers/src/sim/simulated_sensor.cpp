// SimulatedSensor::create: validation of the configuration, the scene view
// computed once, and the live camera / projector / trigger source.
#include <Eigen/Dense>
#include <cmath>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>

#include "sim_live.h"
#include "sim_render.h"
#include "sim_scene.h"
#include "sl/drivers/sim.h"

namespace sl::drivers {

namespace {

[[noreturn]] void fail(const std::string& field, const std::string& problem) {
  throw std::invalid_argument("sim config: " + field + " " + problem);
}

bool finite(const Eigen::Vector3d& v) { return v.allFinite(); }

void validatePinhole(const pipeline::PinholeModel& m, const std::string& name) {
  if (m.width < 2 || m.height < 2) fail(name + ".width/height", "must be >= 2 px");
  if (!(m.fx > 0 && std::isfinite(m.fx))) fail(name + ".fx", "must be > 0");
  if (!(m.fy > 0 && std::isfinite(m.fy))) fail(name + ".fy", "must be > 0");
  if (!std::isfinite(m.cx)) fail(name + ".cx", "must be finite");
  if (!std::isfinite(m.cy)) fail(name + ".cy", "must be finite");
  for (double d : m.distortion)
    if (!std::isfinite(d)) fail(name + ".distortion", "must be finite");
}

void requireNonNegative(double value, const std::string& field) {
  if (!(value >= 0 && std::isfinite(value))) fail(field, "must be finite and >= 0");
}

void requireAlbedo(double albedo, const std::string& field) {
  if (!(albedo >= 0 && albedo <= 1)) fail(field, "must be in [0, 1]");
}

void validateCheckerboard(const SimCheckerboard& b, const Eigen::Vector3d& normal,
                          const std::string& name) {
  if (b.cols < 1 || b.rows < 1) fail(name + ".cols/rows", "must be >= 1 inner corner");
  if (!(b.square_mm > 0 && std::isfinite(b.square_mm))) fail(name + ".square_mm", "must be > 0");
  if (!finite(b.origin)) fail(name + ".origin", "must be finite");
  requireAlbedo(b.dark_albedo, name + ".dark_albedo");
  requireAlbedo(b.light_albedo, name + ".light_albedo");
  // The axes, projected into the plane, must span it.
  const Eigen::Vector3d n = normal.normalized();
  const Eigen::Vector3d x = b.x_axis - n * n.dot(b.x_axis);
  if (!finite(b.x_axis) || x.norm() < 1e-6 * std::max(b.x_axis.norm(), 1e-300))
    fail(name + ".x_axis", "must not be (nearly) parallel to the plane normal");
  const Eigen::Vector3d xu = x.normalized();
  const Eigen::Vector3d y = b.y_axis - n * n.dot(b.y_axis) - xu * xu.dot(b.y_axis);
  if (!finite(b.y_axis) || y.norm() < 1e-6 * std::max(b.y_axis.norm(), 1e-300))
    fail(name + ".y_axis", "must span the plane with x_axis");
}

void validateConfig(const SimConfig& c) {
  if (c.camera_id.empty()) fail("camera_id", "must not be empty");
  validatePinhole(c.rig.camera, "rig.camera");
  validatePinhole(c.rig.projector, "rig.projector");
  if (!c.rig.R.allFinite() ||
      !(c.rig.R.transpose() * c.rig.R).isApprox(Eigen::Matrix3d::Identity(), 1e-6) ||
      c.rig.R.determinant() <= 0)
    fail("rig.R", "must be a rotation matrix");
  if (!finite(c.rig.t)) fail("rig.t", "must be finite");

  if (!(c.camera_fps > 0 && std::isfinite(c.camera_fps))) fail("camera_fps", "must be > 0");
  if (c.bit_depth < 8 || c.bit_depth > 16) fail("bit_depth", "must be in 8..16");
  requireNonNegative(c.projector_brightness_dn, "projector_brightness_dn");
  if (!(c.reference_distance_mm > 0 && std::isfinite(c.reference_distance_mm)))
    fail("reference_distance_mm", "must be > 0");
  requireNonNegative(c.ambient_dn, "ambient_dn");
  requireNonNegative(c.gain_dn_per_electron, "gain_dn_per_electron");
  requireNonNegative(c.read_noise_dn, "read_noise_dn");

  for (std::size_t i = 0; i < c.scene.planes.size(); ++i) {
    const SimPlane& p = c.scene.planes[i];
    const std::string name = "scene.planes[" + std::to_string(i) + "]";
    if (!finite(p.point)) fail(name + ".point", "must be finite");
    if (!finite(p.normal) || p.normal.norm() == 0) fail(name + ".normal", "must be non-zero");
    requireAlbedo(p.albedo, name + ".albedo");
    if (p.checkerboard) validateCheckerboard(*p.checkerboard, p.normal, name + ".checkerboard");
  }
  for (std::size_t i = 0; i < c.scene.spheres.size(); ++i) {
    const SimSphere& s = c.scene.spheres[i];
    const std::string name = "scene.spheres[" + std::to_string(i) + "]";
    if (!finite(s.center)) fail(name + ".center", "must be finite");
    if (!(s.radius > 0 && std::isfinite(s.radius))) fail(name + ".radius", "must be > 0");
    requireAlbedo(s.albedo, name + ".albedo");
  }

  if (c.patterns.empty()) fail("patterns", "must name at least one pattern");
  std::set<std::string> names;
  for (std::size_t i = 0; i < c.patterns.size(); ++i) {
    const pipeline::PatternSpec& p = c.patterns[i];
    const std::string name = "patterns[" + std::to_string(i) + "]";
    if (p.name.empty()) fail(name + ".name", "must not be empty");
    if (!names.insert(p.name).second) fail(name + ".name", "duplicates '" + p.name + "'");
    try {
      p.validate();
    } catch (const std::invalid_argument& e) {
      fail(name, std::string("is invalid: ") + e.what());
    }
    if (p.projector_width != c.rig.projector.width || p.projector_height != c.rig.projector.height)
      fail(name + ".projector_width/height",
           "(" + std::to_string(p.projector_width) + "x" + std::to_string(p.projector_height) +
               ") must equal rig.projector's size (" + std::to_string(c.rig.projector.width) + "x" +
               std::to_string(c.rig.projector.height) + ")");
  }
}

// Immutable after construction; render() is thread-safe.
class SceneRenderer {
 public:
  explicit SceneRenderer(const SimConfig& config) : view_(sim::computeSceneView(config)) {
    response_.gain_dn_per_electron = config.gain_dn_per_electron;
    response_.read_noise_dn = config.read_noise_dn;
    response_.bit_depth = config.bit_depth;
    for (const pipeline::PatternSpec& p : config.patterns) {
      names_.push_back(p.name);
      images_.push_back(pipeline::generatePatternImages(p));
    }
  }

  const SimGroundTruth& groundTruth() const { return view_.ground_truth; }
  const std::vector<std::string>& names() const { return names_; }
  int frameCount(std::size_t pattern) const { return static_cast<int>(images_[pattern].size()); }

  std::size_t patternIndex(const std::string& name) const {
    for (std::size_t i = 0; i < names_.size(); ++i)
      if (names_[i] == name) return i;
    throw std::invalid_argument("SimulatedSensor::render: unknown pattern '" + name + "'");
  }

  cv::Mat render(std::size_t pattern, int frame, std::uint64_t noise_seed) const {
    const std::vector<cv::Mat>& frames = images_.at(pattern);
    if (frame < 0 || frame >= static_cast<int>(frames.size()))
      throw std::out_of_range("SimulatedSensor::render: frame " + std::to_string(frame) +
                              " of pattern '" + names_[pattern] + "' out of range");
    return sim::renderImage(view_.maps, frames[frame], response_, noise_seed);
  }

 private:
  sim::SceneView view_;
  sim::SensorResponse response_;
  std::vector<std::string> names_;
  std::vector<std::vector<cv::Mat>> images_;  // per pattern, projector images in order
};

// Thread-safe: the renderer is immutable, the live state is LiveSchedule's.
class SimulatedSensorImpl final : public SimulatedSensor {
 public:
  explicit SimulatedSensorImpl(SimConfig config)
      : config_(std::move(config)), renderer_(std::make_shared<const SceneRenderer>(config_)) {
    std::vector<ProjectorSequence> sequences;
    for (std::size_t i = 0; i < renderer_->names().size(); ++i)
      sequences.push_back({renderer_->names()[i], renderer_->frameCount(i)});
    // The render function holds the renderer, not the sensor: no cycle.
    std::shared_ptr<const SceneRenderer> renderer = renderer_;
    schedule_ = std::make_shared<sim::LiveSchedule>(
        std::move(sequences), config_.camera_fps, config_.bit_depth, config_.seed,
        [renderer](std::size_t pattern, int frame, std::uint64_t seed) {
          return renderer->render(pattern, frame, seed);
        });
    camera_ = sim::makeLiveCamera(schedule_, config_.camera_id, config_.rig.camera.width,
                                  config_.rig.camera.height);
    projector_ = sim::makeLiveProjector(schedule_, "sim_projector");
    trigger_source_ = sim::makeLiveTriggerSource(schedule_);
  }

  std::shared_ptr<Camera> camera() override { return camera_; }
  std::shared_ptr<Projector> projector() override { return projector_; }
  std::shared_ptr<TriggerSource> triggerSource() override { return trigger_source_; }
  const SimGroundTruth& groundTruth() const override { return renderer_->groundTruth(); }
  const SimConfig& config() const override { return config_; }

  cv::Mat render(const std::string& pattern_name, int frame,
                 std::uint64_t noise_seed) const override {
    return renderer_->render(renderer_->patternIndex(pattern_name), frame, noise_seed);
  }

  SimCounters counters() const override { return schedule_->counters(); }

 private:
  const SimConfig config_;
  const std::shared_ptr<const SceneRenderer> renderer_;
  std::shared_ptr<sim::LiveSchedule> schedule_;
  std::shared_ptr<Camera> camera_;
  std::shared_ptr<Projector> projector_;
  std::shared_ptr<TriggerSource> trigger_source_;
};

}  // namespace

std::shared_ptr<SimulatedSensor> SimulatedSensor::create(SimConfig config) {
  validateConfig(config);
  return std::make_shared<SimulatedSensorImpl>(std::move(config));
}

}  // namespace sl::drivers
