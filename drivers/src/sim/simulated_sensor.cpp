// SimulatedSensor::create: validation of the configuration, the scene view
// computed once, and the live camera / projector / trigger source.
#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <compare>
#include <cstring>
#include <deque>
#include <fstream>
#include <limits>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
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

// 1 TiB: far beyond any machine it runs on, and small enough that the byte
// count cannot overflow.
constexpr std::size_t kMaxSignalCacheMib = std::size_t{1} << 20;

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

void validateTexture(const cv::Mat& albedo, const std::string& field) {
  if (albedo.empty() || albedo.type() != CV_32FC1)
    fail(field, "must be a non-empty CV_32FC1 image");
  if (!cv::checkRange(albedo)) fail(field, "values must be finite");
  double lo = 0, hi = 0;
  cv::minMaxLoc(albedo, &lo, &hi);
  if (!(lo >= 0 && hi <= 1)) fail(field, "values must be in [0, 1]");
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
  for (const auto& [lens, name] : {std::pair{&c.camera_lens, std::string("camera_lens")},
                                   std::pair{&c.projector_lens, std::string("projector_lens")}}) {
    requireNonNegative(lens->f_number, name + ".f_number");
    if (!(lens->pixel_pitch_um > 0 && std::isfinite(lens->pixel_pitch_um)))
      fail(name + ".pixel_pitch_um", "must be > 0");
    if (!(lens->focus_distance_mm > 0 && std::isfinite(lens->focus_distance_mm)))
      fail(name + ".focus_distance_mm", "must be > 0");
  }
  // The lens must focus beyond its focal length (fx * pitch).
  auto checkFocus = [&](const SimLens& lens, const pipeline::PinholeModel& m,
                        const std::string& name) {
    if (lens.f_number > 0 && lens.focus_distance_mm <= 2 * m.fx * lens.pixel_pitch_um * 1e-3)
      fail(name + ".focus_distance_mm", "must exceed twice the focal length fx * pixel_pitch");
  };
  checkFocus(c.camera_lens, c.rig.camera, "camera_lens");
  checkFocus(c.projector_lens, c.rig.projector, "projector_lens");
  if (!(c.exposure_ms > 0 && c.exposure_ms <= 1000.0 / c.camera_fps))
    fail("exposure_ms", "must be > 0 and fit in the frame interval (1000 / camera_fps)");
  if (!(c.reference_exposure_ms > 0 && std::isfinite(c.reference_exposure_ms)))
    fail("reference_exposure_ms", "must be > 0");
  if (!(c.analog_gain > 0 && std::isfinite(c.analog_gain))) fail("analog_gain", "must be > 0");
  if (c.signal_cache_mib > kMaxSignalCacheMib)
    fail("signal_cache_mib", "must be <= " + std::to_string(kMaxSignalCacheMib));
  try {
    sim::makeProjectorResponse(c.projector_gamma, c.projector_response);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("sim config: ") + e.what());
  }

  for (std::size_t i = 0; i < c.scene.planes.size(); ++i) {
    const SimPlane& p = c.scene.planes[i];
    const std::string name = "scene.planes[" + std::to_string(i) + "]";
    if (!finite(p.point)) fail(name + ".point", "must be finite");
    if (!finite(p.normal) || p.normal.norm() == 0) fail(name + ".normal", "must be non-zero");
    requireAlbedo(p.albedo, name + ".albedo");
    if (p.checkerboard) validateCheckerboard(*p.checkerboard, p.normal, name + ".checkerboard");
    if (p.texture) {
      const SimPlaneTexture& t = *p.texture;
      if (p.checkerboard) fail(name + ".texture", "cannot be combined with a checkerboard");
      validateTexture(t.albedo, name + ".texture.albedo");
      if (!finite(t.center)) fail(name + ".texture.center", "must be finite");
      if (!(t.width_mm > 0 && std::isfinite(t.width_mm)))
        fail(name + ".texture.width_mm", "must be > 0");
      const Eigen::Vector3d n = p.normal.normalized();
      if (!finite(t.x_axis) || (t.x_axis - n * n.dot(t.x_axis)).norm() < 1e-6 * t.x_axis.norm())
        fail(name + ".texture.x_axis", "must not be (nearly) parallel to the plane normal");
    }
  }
  for (std::size_t i = 0; i < c.scene.spheres.size(); ++i) {
    const SimSphere& s = c.scene.spheres[i];
    const std::string name = "scene.spheres[" + std::to_string(i) + "]";
    if (!finite(s.center)) fail(name + ".center", "must be finite");
    if (!(s.radius > 0 && std::isfinite(s.radius))) fail(name + ".radius", "must be > 0");
    requireAlbedo(s.albedo, name + ".albedo");
  }

  for (std::size_t i = 0; i < c.scene.cones.size(); ++i) {
    const SimCone& k = c.scene.cones[i];
    const std::string name = "scene.cones[" + std::to_string(i) + "]";
    if (!finite(k.base_center)) fail(name + ".base_center", "must be finite");
    if (!finite(k.axis) || k.axis.norm() == 0) fail(name + ".axis", "must be non-zero");
    if (!(k.radius > 0 && std::isfinite(k.radius))) fail(name + ".radius", "must be > 0");
    if (!(k.height > 0 && std::isfinite(k.height))) fail(name + ".height", "must be > 0");
    requireAlbedo(k.albedo, name + ".albedo");
  }
  for (std::size_t i = 0; i < c.scene.boxes.size(); ++i) {
    const SimBox& b = c.scene.boxes[i];
    const std::string name = "scene.boxes[" + std::to_string(i) + "]";
    if (!finite(b.center)) fail(name + ".center", "must be finite");
    if (!finite(b.size_mm) || (b.size_mm.array() <= 0).any())
      fail(name + ".size_mm", "must be > 0");
    if (!b.rotation.allFinite() ||
        !(b.rotation.transpose() * b.rotation).isApprox(Eigen::Matrix3d::Identity(), 1e-6) ||
        b.rotation.determinant() <= 0)
      fail(name + ".rotation", "must be a rotation matrix");
    requireAlbedo(b.albedo, name + ".albedo");
  }
  for (std::size_t i = 0; i < c.scene.height_fields.size(); ++i) {
    const SimHeightField& h = c.scene.height_fields[i];
    const std::string name = "scene.height_fields[" + std::to_string(i) + "]";
    if (!finite(h.origin)) fail(name + ".origin", "must be finite");
    if (!finite(h.normal) || h.normal.norm() == 0) fail(name + ".normal", "must be non-zero");
    const Eigen::Vector3d n = h.normal.normalized();
    if (!finite(h.x_axis) || (h.x_axis - n * n.dot(h.x_axis)).norm() < 1e-6 * h.x_axis.norm())
      fail(name + ".x_axis", "must not be (nearly) parallel to the normal");
    if (!(h.cell_mm > 0 && std::isfinite(h.cell_mm))) fail(name + ".cell_mm", "must be > 0");
    if (!(h.width_mm >= h.cell_mm && h.length_mm >= h.cell_mm))
      fail(name + ".width_mm/length_mm", "must be >= cell_mm");
    const int cols = static_cast<int>(std::lround(h.width_mm / h.cell_mm)) + 1;
    const int rows = static_cast<int>(std::lround(h.length_mm / h.cell_mm)) + 1;
    if (h.heights_mm.empty()) {
      if (!h.roughness) fail(name, "needs heights_mm or roughness");
      const SimRoughness& r = *h.roughness;
      requireNonNegative(r.rms_mm, name + ".roughness.rms_mm");
      if (!(r.correlation_length_mm > 0))
        fail(name + ".roughness.correlation_length_mm", "must be > 0");
      if (!(r.hurst > 0 && r.hurst <= 1)) fail(name + ".roughness.hurst", "must be in (0, 1]");
    } else if (h.heights_mm.type() != CV_32FC1 || h.heights_mm.rows != rows ||
               h.heights_mm.cols != cols) {
      fail(name + ".heights_mm", "must be CV_32FC1 of " + std::to_string(rows) + " x " +
                                     std::to_string(cols) + " (length/cell + 1 x width/cell + 1)");
    } else if (!cv::checkRange(h.heights_mm)) {
      fail(name + ".heights_mm", "must be finite");
    }
    requireAlbedo(h.albedo, name + ".albedo");
    if (!h.albedo_texture.empty()) validateTexture(h.albedo_texture, name + ".albedo_texture");
  }
  for (std::size_t i = 0; i < c.scene.meshes.size(); ++i) {
    const SimMesh& m = c.scene.meshes[i];
    const std::string name = "scene.meshes[" + std::to_string(i) + "]";
    if (m.triangles.empty()) fail(name, "has no triangles");
    for (const Eigen::Vector3f& v : m.vertices)
      if (!v.allFinite()) fail(name + ".vertices", "must be finite");
    for (const auto& t : m.triangles)
      for (std::int32_t v : t)
        if (v < 0 || static_cast<std::size_t>(v) >= m.vertices.size())
          fail(name + ".triangles", "index " + std::to_string(v) + " out of range");
    if (!m.pose.matrix().allFinite() || !(m.pose.linear().transpose() * m.pose.linear())
                                             .isApprox(Eigen::Matrix3d::Identity(), 1e-6))
      fail(name + ".pose", "must be a finite rigid transform");
    requireAlbedo(m.albedo, name + ".albedo");
  }
  if (c.second_camera) {
    const SimCamera& s = *c.second_camera;
    if (s.camera_id.empty() || s.camera_id == c.camera_id)
      fail("second_camera.camera_id", "must be non-empty and differ from camera_id");
    validatePinhole(s.rig.camera, "second_camera.rig.camera");
    validatePinhole(s.rig.projector, "second_camera.rig.projector");
    if (s.rig.projector.width != c.rig.projector.width ||
        s.rig.projector.height != c.rig.projector.height)
      fail("second_camera.rig.projector", "must have rig.projector's size (same projector)");
    if (!s.rig.R.allFinite() ||
        !(s.rig.R.transpose() * s.rig.R).isApprox(Eigen::Matrix3d::Identity(), 1e-6) ||
        s.rig.R.determinant() <= 0)
      fail("second_camera.rig.R", "must be a rotation matrix");
    if (!finite(s.rig.t)) fail("second_camera.rig.t", "must be finite");
  }
  if (!finite(c.motion.velocity_mm_s)) fail("motion.velocity_mm_s", "must be finite");
  for (std::size_t i = 0; i < c.motion.poses.size(); ++i)
    if (!c.motion.poses[i].matrix().allFinite() ||
        !(c.motion.poses[i].linear().transpose() * c.motion.poses[i].linear())
             .isApprox(Eigen::Matrix3d::Identity(), 1e-6))
      fail("motion.poses[" + std::to_string(i) + "]", "must be a finite rigid transform");

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

// Byte-equal 8-bit images (stops at the first difference).
bool sameImage(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int r = 0; r < a.rows; ++r)
    if (std::memcmp(a.ptr(r), b.ptr(r), a.cols * a.elemSize()) != 0) return false;
  return true;
}

// Immutable after construction but for the signal cache and the placement
// (each guarded by its mutex); render() is thread-safe. Owns the config the scene geometry refers
// to.
class SceneRenderer {
 public:
  explicit SceneRenderer(SimConfig config) : config_(std::move(config)), geometry_(config_.scene) {
    placement_.motion = config_.motion;
    placement_.moving = config_.motion.moving();
    // Exposure and analog gain (see SimConfig): noise referred to the input.
    response_.signal_scale =
        config_.analog_gain * config_.exposure_ms / config_.reference_exposure_ms;
    response_.gain_dn_per_electron = config_.analog_gain * config_.gain_dn_per_electron;
    response_.read_noise_dn = config_.analog_gain * config_.read_noise_dn;
    response_.bit_depth = config_.bit_depth;
    projector_response_ =
        sim::makeProjectorResponse(config_.projector_gamma, config_.projector_response);
    for (const pipeline::PatternSpec& p : config_.patterns) {
      names_.push_back(p.name);
      images_.push_back(pipeline::generatePatternImages(p));
    }
    addCamera(config_.rig);
    if (config_.second_camera) addCamera(config_.second_camera->rig);
    setUpDefocus();
  }

  const SimConfig& config() const { return config_; }
  int cameraCount() const { return static_cast<int>(cameras_.size()); }
  const SimGroundTruth& groundTruth(int camera) const {
    return cameras_.at(camera).view.ground_truth;
  }
  const std::vector<std::string>& names() const { return names_; }
  int frameCount(std::size_t pattern) const { return static_cast<int>(images_[pattern].size()); }

  std::size_t patternIndex(const std::string& name) const {
    for (std::size_t i = 0; i < names_.size(); ++i)
      if (names_[i] == name) return i;
    throw std::invalid_argument("SimulatedSensor::render: unknown pattern '" + name + "'");
  }

  SimGroundTruth groundTruthAt(int camera, int frame) const {
    const CameraView& c = checkedCamera(camera);
    if (frame < 0) throw std::out_of_range("SimulatedSensor::groundTruthAt: frame < 0");
    const Placement place = placement();
    if (!place.moving) return c.view.ground_truth;
    return sim::computeSceneView(config_, geometry_, c.rig, c.rays, cameraToScene(c, frame, place),
                                 true)
        .ground_truth;
  }

  // const: the renderer is shared as const with the live camera's render
  // function; the placement is its one mutable, locked state.
  void setMotion(const Eigen::Isometry3d& base, const SimMotion& motion) const {
    Placement place{base, motion, !base.matrix().isIdentity(0) || motion.moving()};
    std::lock_guard lock(placement_mutex_);
    placement_ = std::move(place);
  }

  cv::Mat render(int camera, std::size_t pattern, int frame, std::uint64_t noise_seed) const {
    const CameraView& c = checkedCamera(camera);
    const std::vector<const sim::ProjectorFrame*>& frames = frames_.at(pattern);
    if (frame < 0 || frame >= static_cast<int>(frames.size()))
      throw std::out_of_range("SimulatedSensor::render: frame " + std::to_string(frame) +
                              " of pattern '" + names_[pattern] + "' out of range");
    const sim::ProjectorFrame& projected = *frames[static_cast<std::size_t>(frame)];
    const Placement place = placement();
    if (!place.moving) {
      // A static scene: the signal of (camera, projector frame) at the
      // configured pose, from the scene view computed once.
      const SignalKey key{camera, &projected, false, {}};
      if (const std::shared_ptr<const cv::Mat> signal = cachedSignal(key, [&] {
            return sim::renderSignal(c.view.maps, projected, projector_response_,
                                     c.camera_blur_passes);
          }))
        return sim::renderFromSignal(*signal, response_, noise_seed);
      return sim::renderImage(c.view.maps, projected, response_, noise_seed, projector_response_,
                              c.camera_blur_passes);
    }
    // Moving sensor: ray-cast this image's pose (camera rays undistorted once),
    // into per-thread buffers reused from image to image. The pose (camera
    // to scene) with the camera and the projector frame determines the
    // signal exactly, so sequences that repeat their poses hit the cache.
    const Eigen::Isometry3d to_scene = cameraToScene(c, frame, place);
    thread_local sim::SceneView moved;
    auto castMoved = [&] {
      sim::computeSceneViewInto(config_, geometry_, c.rig, c.rays, to_scene, false, moved);
      assignDefocus(c, moved.maps);
    };
    SignalKey key{camera, &projected, true, {}};
    Eigen::Map<Eigen::Matrix4d>(key.pose.data()) = to_scene.matrix();
    if (const std::shared_ptr<const cv::Mat> signal = cachedSignal(key, [&] {
          castMoved();
          return sim::renderSignal(moved.maps, projected, projector_response_,
                                   c.camera_blur_passes);
        }))
      return sim::renderFromSignal(*signal, response_, noise_seed);
    castMoved();
    return sim::renderImage(moved.maps, projected, response_, noise_seed, projector_response_,
                            c.camera_blur_passes);
  }

  SimSignalCacheStats signalCacheStats() const {
    std::lock_guard lock(signal_mutex_);
    SimSignalCacheStats s = signal_stats_;
    s.entries = signals_.size();
    s.bytes = signal_bytes_;
    s.capacity_bytes = signalCacheCapacity();
    return s;
  }

 private:
  struct CameraView {
    pipeline::CameraProjectorCalibration rig;
    Eigen::Isometry3d to_first;  // X_first = to_first * X_this
    sim::CameraRays rays;
    sim::SceneView view;         // at the configured pose (image 0)
    int camera_blur_passes = 0;  // 0: sharp
  };

  static double meanFocalPx(const pipeline::PinholeModel& m) { return 0.5 * (m.fx + m.fy); }

  // Defocus. Camera: the blur passes for the depth range each camera sees
  // in the configured pose (widened for a moving sensor; beyond it the
  // per-pass kernel is capped), and each pixel's kernel. Projector: the
  // sigma of every projector pixel from the depth of the surface it lights
  // in the configured pose (kept for all poses of a moving sensor: the
  // depths change by the motion, a few mm, the blur by a small fraction),
  // and the blurred light of each distinct pattern image.
  void setUpDefocus() {
    for (CameraView& c : cameras_) {
      if (!(config_.camera_lens.f_number > 0)) break;
      double hi = 0;
      for (float z : c.view.maps.camera_depth_mm)
        if (z > 0) hi = std::max(hi, config_.camera_lens.blurSigmaPx(z, meanFocalPx(c.rig.camera)));
      if (config_.motion.moving()) hi = hi * 1.3 + 0.2;
      c.camera_blur_passes = sim::cameraBlurPasses(hi);
      assignDefocus(c, c.view.maps);
    }

    sim::BlurLevels projector_blur;
    cv::Mat sigma;
    if (config_.projector_lens.f_number > 0) {
      constexpr int kDepthStep = 4;  // ray-cast every 4th projector pixel
      sigma =
          sim::projectorDepthMap(geometry_, config_.rig, Eigen::Isometry3d::Identity(), kDepthStep);
      const double fx = meanFocalPx(config_.rig.projector);
      double lo = std::numeric_limits<double>::infinity(), hi = 0;
      for (int r = 0; r < sigma.rows; ++r) {
        float* row = sigma.ptr<float>(r);
        for (int c = 0; c < sigma.cols; ++c) {
          row[c] = static_cast<float>(config_.projector_lens.blurSigmaPx(row[c], fx));
          if (row[c] > 0) lo = std::min(lo, double(row[c])), hi = std::max(hi, double(row[c]));
        }
      }
      // Sigma steps of 2^(1/4): the variance-linear blend of neighbouring
      // levels is then within about 0.5 % of the Gaussian's modulation.
      constexpr int kMaxLevels = 10;
      projector_blur = sim::chooseBlurLevels(lo, hi, std::pow(2.0, 0.25), kMaxLevels);
    }
    const sim::ProjectorBlur blur = sim::makeProjectorBlur(projector_blur, sigma);

    // Distinct pattern images (patterns often share frames) get one frame each.
    std::vector<const cv::Mat*> distinct;
    for (std::size_t p = 0; p < images_.size(); ++p) {
      frames_.emplace_back();
      for (const cv::Mat& image : images_[p]) {
        std::size_t k = 0;
        while (k < distinct.size() && !sameImage(*distinct[k], image)) ++k;
        if (k == distinct.size()) {
          distinct.push_back(&image);
          storage_.push_back(
              sim::makeProjectorFrame(image, projector_response_, blur));
        }
        frames_.back().push_back(&storage_[k]);
      }
    }
  }

  // What determines a camera's noise-free signal exactly: the camera, the
  // projector frame and the pose (camera to scene, the 4 x 4 matrix compared exactly;
  // all zero for the static view computed at creation).
  struct SignalKey {
    int camera = 0;
    const sim::ProjectorFrame* frame = nullptr;
    bool moving = false;
    std::array<double, 16> pose{};
    auto operator<=>(const SignalKey&) const = default;
  };

  std::size_t signalCacheCapacity() const { return config_.signal_cache_mib << 20; }

  // The cached signal for `key`, made by `compute` (a CV_32FC1 of the camera's
  // size) on first use; null when the cache is off or the signal does not fit
  // (the caller then renders in full). Least recently used signals are
  // evicted to make room. Concurrent callers of one key wait for one compute.
  template <typename Compute>
  std::shared_ptr<const cv::Mat> cachedSignal(const SignalKey& key, Compute&& compute) const {
    const CameraView& c = cameras_[static_cast<std::size_t>(key.camera)];
    const std::size_t bytes =
        static_cast<std::size_t>(c.view.maps.width) * c.view.maps.height * sizeof(float);
    const std::size_t capacity = signalCacheCapacity();
    std::shared_ptr<SignalEntry> entry;
    {
      std::lock_guard lock(signal_mutex_);
      if (bytes > capacity) {
        ++signal_stats_.uncached;
        return nullptr;
      }
      if (const auto found = signals_.find(key); found != signals_.end()) {
        ++signal_stats_.hits;
        signal_lru_.splice(signal_lru_.begin(), signal_lru_, found->second->lru);
        entry = found->second;
      } else {
        while (signal_bytes_ + bytes > capacity) {
          const auto oldest = signals_.find(signal_lru_.back());
          signal_bytes_ -= oldest->second->bytes;
          signals_.erase(oldest);
          signal_lru_.pop_back();
          ++signal_stats_.evictions;
        }
        ++signal_stats_.misses;
        entry = std::make_shared<SignalEntry>();
        entry->bytes = bytes;
        signal_lru_.push_front(key);
        entry->lru = signal_lru_.begin();
        signals_.emplace(key, entry);
        signal_bytes_ += bytes;
      }
    }
    // An entry evicted meanwhile stays valid for whoever holds it.
    std::call_once(entry->once,
                   [&] { entry->signal = std::make_shared<const cv::Mat>(compute()); });
    return entry->signal;
  }

  void assignDefocus(const CameraView& c, sim::RenderMaps& maps) const {
    if (c.camera_blur_passes > 0)
      sim::assignCameraBlur(maps, c.camera_blur_passes, config_.camera_lens,
                            meanFocalPx(c.rig.camera));
  }

  void addCamera(const pipeline::CameraProjectorCalibration& rig) {
    CameraView c;
    c.rig = rig;
    c.to_first = pipeline::cameraToCamera(rig, config_.rig);  // camera k -> sensor frame
    c.rays = sim::computeCameraRays(rig.camera);
    c.view = sim::computeSceneView(config_, geometry_, rig, c.rays, c.to_first, true);
    cameras_.push_back(std::move(c));
  }

  const CameraView& checkedCamera(int camera) const {
    if (camera < 0 || camera >= cameraCount())
      throw std::out_of_range("SimulatedSensor: camera index " + std::to_string(camera) +
                              " out of range (" + std::to_string(cameraCount()) + " cameras)");
    return cameras_[static_cast<std::size_t>(camera)];
  }

  // Where the sensor is: SimConfig::motion from the configured pose, or what
  // setMotion() said.
  struct Placement {
    Eigen::Isometry3d base = Eigen::Isometry3d::Identity();
    SimMotion motion;
    bool moving = false;
  };
  Placement placement() const {
    std::lock_guard lock(placement_mutex_);
    return placement_;
  }

  Eigen::Isometry3d cameraToScene(const CameraView& c, int frame, const Placement& place) const {
    return place.base * place.motion.poseAt(frame, config_.camera_fps) * c.to_first;
  }

  const SimConfig config_;
  const sim::SceneGeometry geometry_;
  std::vector<CameraView> cameras_;
  sim::SensorResponse response_;
  sim::ProjectorResponse projector_response_;
  std::vector<std::string> names_;
  std::vector<std::vector<cv::Mat>> images_;  // per pattern, projector images in order
  std::deque<sim::ProjectorFrame> storage_;   // distinct frames (stable addresses)
  std::vector<std::vector<const sim::ProjectorFrame*>> frames_;  // per pattern, in order

  // Noise-free signals (see cachedSignal), most recently used first in
  // signal_lru_.
  struct SignalEntry {
    std::once_flag once;
    std::shared_ptr<const cv::Mat> signal;
    std::size_t bytes = 0;
    std::list<SignalKey>::iterator lru;  // guarded by signal_mutex_
  };
  mutable std::mutex signal_mutex_;
  mutable std::map<SignalKey, std::shared_ptr<SignalEntry>> signals_;  // guarded by signal_mutex_
  mutable std::list<SignalKey> signal_lru_;                            // guarded by signal_mutex_
  mutable std::size_t signal_bytes_ = 0;                               // guarded by signal_mutex_
  mutable SimSignalCacheStats signal_stats_;                           // guarded by signal_mutex_
  mutable std::mutex placement_mutex_;
  mutable Placement placement_;  // guarded by placement_mutex_
};

// Thread-safe: the renderer is immutable, the live state is LiveSchedule's.
class SimulatedSensorImpl final : public SimulatedSensor {
 public:
  explicit SimulatedSensorImpl(SimConfig config)
      : renderer_(std::make_shared<const SceneRenderer>(std::move(config))) {
    std::vector<ProjectorSequence> sequences;
    for (std::size_t i = 0; i < renderer_->names().size(); ++i)
      sequences.push_back({renderer_->names()[i], renderer_->frameCount(i)});
    const SimConfig& c = renderer_->config();
    // The render function holds the renderer, not the sensor: no cycle.
    std::shared_ptr<const SceneRenderer> renderer = renderer_;
    schedule_ = std::make_shared<sim::LiveSchedule>(
        std::move(sequences), c.camera_fps, c.bit_depth, c.seed,
        [renderer](int camera, std::size_t pattern, int frame, std::uint64_t seed) {
          return renderer->render(camera, pattern, frame, seed);
        },
        renderer_->cameraCount());
    cameras_.push_back(
        sim::makeLiveCamera(schedule_, 0, c.camera_id, c.rig.camera.width, c.rig.camera.height));
    if (c.second_camera)
      cameras_.push_back(sim::makeLiveCamera(schedule_, 1, c.second_camera->camera_id,
                                             c.second_camera->rig.camera.width,
                                             c.second_camera->rig.camera.height));
    projector_ = sim::makeLiveProjector(schedule_, "sim_projector");
    trigger_source_ = sim::makeLiveTriggerSource(schedule_);
  }

  std::shared_ptr<Camera> camera() override { return cameras_.front(); }
  std::vector<std::shared_ptr<Camera>> cameras() override { return cameras_; }
  std::shared_ptr<Projector> projector() override { return projector_; }
  std::shared_ptr<TriggerSource> triggerSource() override { return trigger_source_; }
  const SimGroundTruth& groundTruth() const override { return renderer_->groundTruth(0); }
  SimGroundTruth groundTruthAt(int camera, int frame) const override {
    return renderer_->groundTruthAt(camera, frame);
  }
  void setMotion(const Eigen::Isometry3d& base, const SimMotion& motion) override {
    renderer_->setMotion(base, motion);
  }
  const SimConfig& config() const override { return renderer_->config(); }

  cv::Mat render(const std::string& pattern_name, int frame,
                 std::uint64_t noise_seed) const override {
    return renderer_->render(0, renderer_->patternIndex(pattern_name), frame, noise_seed);
  }
  cv::Mat render(int camera, const std::string& pattern_name, int frame,
                 std::uint64_t noise_seed) const override {
    return renderer_->render(camera, renderer_->patternIndex(pattern_name), frame, noise_seed);
  }

  SimCounters counters() const override { return schedule_->counters(); }
  SimSignalCacheStats signalCacheStats() const override { return renderer_->signalCacheStats(); }

 private:
  const std::shared_ptr<const SceneRenderer> renderer_;
  std::shared_ptr<sim::LiveSchedule> schedule_;
  std::vector<std::shared_ptr<Camera>> cameras_;
  std::shared_ptr<Projector> projector_;
  std::shared_ptr<TriggerSource> trigger_source_;
};

}  // namespace

cv::Mat loadAlbedoTexture(const std::string& path) {
  if (!std::ifstream(path))
    throw std::runtime_error("albedo texture '" + path + "': cannot be opened");
  const cv::Mat raw = cv::imread(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
  if (raw.empty())
    throw std::runtime_error("albedo texture '" + path + "': cannot be read as an image");
  if (raw.depth() != CV_8U && raw.depth() != CV_16U)
    throw std::runtime_error("albedo texture '" + path + "': must be 8 or 16 bit");
  cv::Mat albedo;
  raw.convertTo(albedo, CV_32FC1, raw.depth() == CV_8U ? 1.0 / 255 : 1.0 / 65535);
  return albedo;
}

cv::Mat heightsFromImage(const cv::Mat& unit_image, double min_mm, double max_mm, int rows,
                         int cols) {
  if (unit_image.empty() || unit_image.type() != CV_32FC1 || rows < 2 || cols < 2)
    throw std::invalid_argument("heightsFromImage: needs a CV_32FC1 image and a grid >= 2 x 2");
  cv::Mat heights(rows, cols, CV_32FC1);
  const double sx = double(unit_image.cols - 1) / (cols - 1);
  const double sy = double(unit_image.rows - 1) / (rows - 1);
  for (int r = 0; r < rows; ++r) {
    const double y = r * sy;
    const int y0 = std::min(int(y), std::max(unit_image.rows - 2, 0));
    const int y1 = std::min(y0 + 1, unit_image.rows - 1);
    const double fy = y - y0;
    for (int c = 0; c < cols; ++c) {
      const double x = c * sx;
      const int x0 = std::min(int(x), std::max(unit_image.cols - 2, 0));
      const int x1 = std::min(x0 + 1, unit_image.cols - 1);
      const double fx = x - x0;
      auto at = [&](int yy, int xx) { return double(unit_image.at<float>(yy, xx)); };
      const double v = (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x1)) +
                       fy * ((1 - fx) * at(y1, x0) + fx * at(y1, x1));
      heights.at<float>(r, c) = static_cast<float>(min_mm + (max_mm - min_mm) * v);
    }
  }
  return heights;
}

double SimLens::blurSigmaPx(double z_mm, double fx_px) const {
  if (f_number <= 0 || !(z_mm > 0)) return 0;
  const double focal_mm = fx_px * pixel_pitch_um * 1e-3;
  const double disk_px = fx_px * focal_mm / (f_number * (focus_distance_mm - focal_mm)) *
                         std::abs(z_mm - focus_distance_mm) / z_mm;
  return disk_px / 4;
}

bool SimMotion::moving() const {
  if (!poses.empty()) {
    for (const Eigen::Isometry3d& p : poses)
      if (p.matrix() != Eigen::Matrix4d::Identity()) return true;
    return false;
  }
  return velocity_mm_s != Eigen::Vector3d::Zero();
}

Eigen::Isometry3d SimMotion::poseAt(int frame, double camera_fps) const {
  if (!poses.empty()) return poses[static_cast<std::size_t>(frame) % poses.size()];
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = velocity_mm_s * (frame / camera_fps);
  return pose;
}

std::shared_ptr<SimulatedSensor> SimulatedSensor::create(SimConfig config) {
  validateConfig(config);
  for (SimHeightField& h : config.scene.height_fields)
    if (h.heights_mm.empty()) h.heights_mm = sim::generateRoughHeights(h, *h.roughness);
  return std::make_shared<SimulatedSensorImpl>(std::move(config));
}

}  // namespace sl::drivers
