// The simulated sensor: one or two cameras and a projector addressed like the
// LightCrafter 4500, looking at a scene of planes, spheres, cones, boxes,
// height fields and triangle meshes (constant, checkerboard or textured
// albedo), optionally while the sensor moves. It renders what the camera
// would see for each projected pattern (projector intensity response,
// thin-lens defocus of projector and camera, Lambertian shading, projector
// shadows, ambient light, exposure and gain, shot and read noise,
// quantisation and saturation) and plays the trigger schedule of the real
// sensor in real time: the camera exposes every dt_img = 1/fps, each sequence
// of frame_count patterns starts with a trigger event.
//
// Rendering is cheap because the projector coordinate seen by a camera pixel
// does not depend on the pattern: it is computed once per sensor pose (once
// per scene for a static sensor; once per image when the sensor moves, from
// camera rays undistorted once). The projector's defocus is baked into the
// pattern images once (blurred per projector pixel for the depth it lights);
// the camera's is a few cheap per-pixel filter passes per image. The
// noise-free signal of each (camera, pose, pattern frame) is cached
// (SimConfig::signal_cache_mib): a moving sensor repeats its poses every
// sequence, so in a live run only the noise is drawn per image.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core/mat.hpp>

#include "sl/drivers/camera.h"
#include "sl/drivers/projector.h"
#include "sl/drivers/trigger_source.h"
#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/pattern_spec.h"

namespace sl::drivers {

// A checkerboard printed on a plane (a calibration target). The board has
// cols x rows inner corners, i.e. (cols + 1) x (rows + 1) squares; corner
// (c, r) lies at origin + square_mm * (c * x + r * y), where x and y are the
// in-plane unit axes made from x_axis and y_axis (x_axis projected into the
// plane; y_axis projected perpendicular to the normal and to x). The square
// that touches inner corner (0, 0) from the -x, -y side is dark; squares
// alternate from there. Outside the squares the plane keeps its own albedo
// (the board's margin). The camera sees each pixel's albedo averaged over the
// pixel's footprint on the plane, so edges are anti-aliased as on a sensor.
struct SimCheckerboard {
  int cols = 13;                         // inner corners along x
  int rows = 9;                          // inner corners along y
  double square_mm = 10;
  Eigen::Vector3d origin{0, 0, 600};     // mm, camera frame; projected onto the plane
  Eigen::Vector3d x_axis{1, 0, 0};       // need not be unit or exactly in the plane
  Eigen::Vector3d y_axis{0, 1, 0};
  double dark_albedo = 0.15;             // [0, 1]
  double light_albedo = 0.8;             // [0, 1]
};

// An albedo image (e.g. a photo of a texture) on a plane: CV_32FC1 values in
// [0, 1], sampled bilinearly at each surface point (no averaging over a
// camera pixel's footprint: give images no finer than the camera resolves).
// The image is width_mm wide (its height follows its aspect ratio), centred
// on `center` (projected onto the plane); its columns run along x_axis
// projected into the plane, its rows along x x n (n the plane's normal), so
// the image reads upright from the side the normal faces. Outside it the
// plane keeps its own albedo.
struct SimPlaneTexture {
  cv::Mat albedo;
  Eigen::Vector3d center{0, 0, 600};  // mm, camera frame
  Eigen::Vector3d x_axis{1, 0, 0};
  double width_mm = 100;
};

// Reads an albedo image (PNG or any format OpenCV reads; 8 or 16 bit; colour
// is converted to grey) scaled to [0, 1]. Throws std::runtime_error naming
// the file.
cv::Mat loadAlbedoTexture(const std::string& path);

struct SimPlane {
  Eigen::Vector3d point{0, 0, 600};   // mm, camera frame
  Eigen::Vector3d normal{0, 0, -1};   // need not be unit; faces the sensor
  double albedo = 0.8;                // diffuse reflectance in [0, 1]
  std::optional<SimCheckerboard> checkerboard{};  // none: constant albedo
  std::optional<SimPlaneTexture> texture{};       // not with a checkerboard
};

struct SimSphere {
  Eigen::Vector3d center{0, 0, 550};  // mm, camera frame
  double radius = 50;                 // mm
  double albedo = 0.8;
};

// A solid right circular cone: lateral surface plus the base disk.
struct SimCone {
  Eigen::Vector3d base_center{0, 0, 600};  // mm, camera frame
  Eigen::Vector3d axis{0, 0, -1};          // base -> apex; need not be unit
  double radius = 20;                      // mm, base radius
  double height = 30;                      // mm, base to apex
  double albedo = 0.8;
};

// A solid box: size_mm along its own axes, rotation = box axes in the camera
// frame (columns).
struct SimBox {
  Eigen::Vector3d center{0, 0, 600};   // mm, camera frame
  Eigen::Vector3d size_mm{50, 50, 50};
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  double albedo = 0.8;
};

// A random rough surface: a Gaussian field whose power spectrum is flat up to
// 1 / correlation_length_mm and falls as k^-(2 + 2 hurst) above it (a
// self-affine surface), scaled to rms_mm exactly. Deterministic given seed.
struct SimRoughness {
  double rms_mm = 0.1;
  double correlation_length_mm = 5.0;
  double hurst = 0.8;
  std::uint64_t seed = 1;
};

// A height field over a rectangle: the surface point of cell (i, j) is
// origin + (-width/2 + i * cell) x + (-length/2 + j * cell) y + H(j, i) n,
// bilinear between samples (x = x_axis projected into the plane, y = n x x,
// n = normal, unit). Only the top surface exists (no side walls); heights
// are along the normal, which faces the sensor.
struct SimHeightField {
  Eigen::Vector3d origin{0, 0, 600};  // mm, camera frame: centre of the rectangle at height 0
  Eigen::Vector3d normal{0, 0, -1};
  Eigen::Vector3d x_axis{1, 0, 0};
  double width_mm = 170;              // along x
  double length_mm = 170;             // along y
  double cell_mm = 0.5;
  // CV_32FC1 heights (mm), rows along y, cols along x; must have
  // round(length/cell) + 1 rows and round(width/cell) + 1 cols. Empty:
  // generated from `roughness` when the sensor is created.
  cv::Mat heights_mm;
  std::optional<SimRoughness> roughness{};
  double albedo = 0.8;
  // Optional albedo image (CV_32FC1, [0, 1]) stretched over the rectangle:
  // column 0 at -width/2 and the last at +width/2 along x, row 0 at
  // -length/2 and the last at +length/2 along y (as heights_mm), bilinear.
  // Empty: constant albedo.
  cv::Mat albedo_texture;
};

// A triangle mesh (e.g. from a PLY file): vertices in the mesh's own frame,
// placed in the camera frame by pose (X = pose * vertex, mm). Triangles are
// two-sided and flat-shaded (the face normal); the mesh need not be closed.
// Ray casting uses a bounding volume hierarchy, so meshes of a few million
// triangles stay interactive.
struct SimMesh {
  std::vector<Eigen::Vector3f> vertices;                 // mm, mesh frame
  std::vector<std::array<std::int32_t, 3>> triangles;   // vertex indices
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  double albedo = 0.8;
};

// Reads a PLY file (ascii or binary_little_endian): the x, y, z properties
// of the `vertex` element, times `scale` (e.g. 1000 for a file in metres),
// and the `vertex_indices` (or `vertex_index`) lists of the `face` element,
// polygons split into triangle fans. Other elements and properties are
// skipped. Throws std::runtime_error naming the file and the problem.
SimMesh loadPlyMesh(const std::string& path, double scale = 1.0);

// Heights (CV_32FC1, rows x cols, as SimHeightField::heights_mm) from an
// image with values in [0, 1] (e.g. loadAlbedoTexture of a grey PNG):
// min_mm + (max_mm - min_mm) * value, resampled bilinearly over the grid
// (image corners on the grid's corners).
cv::Mat heightsFromImage(const cv::Mat& unit_image, double min_mm, double max_mm, int rows,
                         int cols);

struct SimScene {
  std::vector<SimPlane> planes;
  std::vector<SimSphere> spheres;
  std::vector<SimCone> cones;
  std::vector<SimBox> boxes;
  std::vector<SimHeightField> height_fields;
  std::vector<SimMesh> meshes;
};

// A composite: appends every object of `group` (given in the group's own
// frame) to `scene`, moved by `pose` (X_scene = pose * X_group).
void appendTransformed(SimScene& scene, const SimScene& group, const Eigen::Isometry3d& pose);

// Motion of the sensor during a pattern sequence. The scene is given in the
// camera frame of the sequence's first image (frame 0); image i of every
// sequence is rendered with the sensor at its exposure time, i.e. the scene
// seen through the inverse of the sensor's motion. Each sequence starts again
// from the configured pose (so a long live run keeps the scene in view).
struct SimMotion {
  // Linear motion: sensor velocity in the frame-0 camera frame (mm/s); image i
  // is exposed i / camera_fps after image 0.
  Eigen::Vector3d velocity_mm_s = Eigen::Vector3d::Zero();
  // Or one sensor pose per image (image i uses poses[i % size]): camera frame
  // of image i in that of image 0 (X_0 = pose * X_i, mm). Non-empty: used
  // instead of velocity_mm_s.
  std::vector<Eigen::Isometry3d> poses;

  bool moving() const;
  // Pose of the sensor for image `frame` of a sequence.
  Eigen::Isometry3d poseAt(int frame, double camera_fps) const;
};

// Thin-lens defocus of a camera or of the projector. A lens of focal length
// f = fx * pixel_pitch, focused at focus_distance_mm with f-number N (aperture
// diameter f / N), images a point at distance z along its optical axis as a
// disk of diameter (in pixels, fx the device's focal length in px)
//   c = fx * f / (N * (focus_distance_mm - f)) * |z - focus_distance_mm| / z
// rendered as a Gaussian of the same second moment: sigma = c / 4.
// The camera's blur acts on the image (each pixel's light spread by the sigma
// of its own surface depth, before noise); the projector's blurs the pattern
// in projector space by the sigma of the lit surface's depth, so the light
// a surface receives is the pattern seen through the defocused lens.
// f_number 0 is a pinhole: no blur.
struct SimLens {
  double focus_distance_mm = 550;
  double f_number = 4;
  double pixel_pitch_um = 3.45;

  // Gaussian sigma (px) of the blur at distance z_mm for focal length fx_px.
  double blurSigmaPx(double z_mm, double fx_px) const;
};

// A further camera seeing the same projector, with its own rig calibration
// (camera model and projector pose relative to that camera).
struct SimCamera {
  std::string camera_id = "sim_left";
  pipeline::CameraProjectorCalibration rig;
};

struct SimConfig {
  std::string camera_id = "sim_top";
  // True geometry of the rig: camera and projector models, projector pose.
  pipeline::CameraProjectorCalibration rig;
  // Optional second camera ("left"), rendered on the same projector schedule.
  // Its rig's projector must have the first rig's projector size.
  std::optional<SimCamera> second_camera{};
  SimScene scene;
  SimMotion motion;
  std::vector<pipeline::PatternSpec> patterns;  // sequences the projector knows (any family)

  double camera_fps = 30.0;       // dt_img = 1 / fps
  int bit_depth = 8;              // 8..16
  // Radiometry in camera DN: a white (albedo 1) surface facing the projector
  // at reference_distance_mm, lit by a full-white pattern, reads
  // projector_brightness_dn above the ambient level.
  //
  // All DN values here are on the 8-bit scale (full scale 255) whatever
  // bit_depth is. A pixel's signal is
  //   S = ambient_dn * albedo
  //       + projector_brightness_dn * albedo * cos(incidence)
  //         * (reference_distance_mm / distance to projector)^2 * P / 255
  // with P the projector image (8 bits) sampled bilinearly at the pixel's
  // projector coordinate (P = 0 where not lit). Noise is Gaussian with
  // variance gain_dn_per_electron * S + read_noise_dn^2 (8-bit DN^2), then
  // the image value is round((S + noise) * (2^bit_depth - 1) / 255) clamped
  // to [0, 2^bit_depth - 1]: a deeper ADC sees the same relative noise, with
  // finer quantisation. bit_depth 8 gives CV_8UC1, 9..16 CV_16UC1.
  //
  // Exposure and gain: the DN values above are those at exposure_ms =
  // reference_exposure_ms and analog_gain = 1. The camera collects light for
  // exposure_ms (the projector shows each pattern for the whole exposure, and
  // ambient light is collected for as long), so S scales with
  // exposure_ms / reference_exposure_ms; the analog gain G multiplies the
  // signal and, since both noises are referred to the sensor's input, the
  // shot-noise std (var = G * gain_dn_per_electron * signal after gain) and
  // the read noise (G * read_noise_dn). The model in full, on the 8-bit scale:
  //   S' = G * S * exposure_ms / reference_exposure_ms
  //   value = clamp(round((S' + N(0, G k S' + (G r)^2)) * (2^bits - 1) / 255),
  //                 0, 2^bits - 1)
  // with k = gain_dn_per_electron and r = read_noise_dn: saturation is the
  // ADC's full scale, reached by signal plus noise (a saturated pixel reads
  // exactly 2^bits - 1). Typical machine-vision outputs are Mono8, Mono10 and
  // Mono12 (bit_depth 8, 10, 12).
  double projector_brightness_dn = 220.0;
  double reference_distance_mm = 500.0;
  double ambient_dn = 10.0;       // ambient light on an albedo-1 surface
  double gain_dn_per_electron = 0.0084;  // shot noise: var = gain * signal (DN^2)
  double read_noise_dn = 0.05;          // std of additive Gaussian noise (DN)
  double exposure_ms = 4.0;            // camera exposure, <= 1000 / camera_fps
  double reference_exposure_ms = 4.0; // exposure at which the DN values above hold
  double analog_gain = 1.0;            // linear factor (> 0), see above

  // Projector intensity response: the light emitted for an 8-bit pattern
  // level L, as a fraction of full white. The LightCrafter 4500 in pattern
  // mode is linear (the default); a video-mode projector is not, and the
  // non-linearity turns the sinusoids of a phase-shifting pattern into
  // periodic phase errors. With projector_response empty the response is
  // (L / 255)^projector_gamma. Otherwise projector_response holds n >= 2
  // samples in [0, 1] of the response at L = 255 * k / (n - 1), k = 0..n-1,
  // linear in between, and projector_gamma must be 1. The light P in the
  // signal formula above is then 255 * response(L), not L.
  double projector_gamma = 1.0;
  std::vector<double> projector_response;
  // Defocus (see SimLens): the cameras' lens (the second camera has the same)
  // and the projector's. Defaults: both focused at 550 mm at f/4, a 3.45 um
  // pixel camera (f = 8.3 mm) and the LightCrafter's 5.4 um addressed pixel
  // (f = 11.9 mm): at 0.45-0.7 m the blur sigma stays below about 0.5 px
  // (camera) and 0.7 px (projector).
  SimLens camera_lens{550, 4, 3.45};
  SimLens projector_lens{550, 4, 5.4};
  // Noise seed. Live frame with camera frame_id f uses a seed hashed from
  // (seed, f), so a run is reproducible apart from dropped frames.
  std::uint64_t seed = 1;

  // Signal cache (MiB, 1 MiB = 2^20 bytes; 0 disables it): the noise-free
  // signal of a camera image (CV_32FC1, 4 bytes per camera pixel) is kept
  // per (camera, sensor pose, projector frame), the three things that
  // determine it, so that a static scene, and a moving sensor whose
  // sequences repeat the same poses (SimMotion), ray-cast and shade each
  // distinct image once; each image then costs only its noise. Least
  // recently used signals are evicted first; the cached signals never exceed
  // the bound (a signal larger than it is not cached). Images are bit for
  // bit the same with and without the cache.
  std::size_t signal_cache_mib = 256;
};

// The signal cache since creation (see SimConfig::signal_cache_mib).
struct SimSignalCacheStats {
  std::uint64_t hits = 0;       // images rendered from a cached signal
  std::uint64_t misses = 0;     // signals computed and cached
  std::uint64_t evictions = 0;  // signals dropped to stay within the bound
  std::uint64_t uncached = 0;   // images rendered in full (cache off or signal too large)
  std::size_t entries = 0;      // signals cached now
  std::size_t bytes = 0;        // their size; <= capacity_bytes
  std::size_t capacity_bytes = 0;
};

// Counts of the live schedule since creation.
struct SimCounters {
  std::uint64_t frames_delivered = 0;
  std::uint64_t frames_dropped = 0;     // grab() fell more than 8 frames behind
  std::uint64_t triggers_delivered = 0;
  std::uint64_t triggers_dropped = 0;   // next() fell more than 8 triggers behind
};

// Per-pixel ground truth of the camera view (camera size).
struct SimGroundTruth {
  cv::Mat depth_mm;  // CV_32FC1 z in the camera frame, NaN where no surface
  cv::Mat xyz_mm;    // CV_32FC3 point in the camera frame, NaN where no surface
  cv::Mat up;        // CV_32FC1 projector column seen by the pixel, NaN if not lit
  cv::Mat vp;        // CV_32FC1 projector row seen by the pixel, NaN if not lit
  cv::Mat lit;       // CV_8UC1 255 where the surface is visible to the projector
};

// Thread-safe: the camera, projector and trigger source it hands out may be
// used from different threads.
class SimulatedSensor {
 public:
  // Throws std::invalid_argument naming the bad field.
  static std::shared_ptr<SimulatedSensor> create(SimConfig config);
  virtual ~SimulatedSensor() = default;

  // The first camera (= cameras()[0]).
  virtual std::shared_ptr<Camera> camera() = 0;
  // All cameras: the first, then second_camera if configured.
  virtual std::vector<std::shared_ptr<Camera>> cameras() = 0;
  virtual std::shared_ptr<Projector> projector() = 0;
  virtual std::shared_ptr<TriggerSource> triggerSource() = 0;

  // Ground truth of the first camera with the sensor at its configured pose
  // (image 0 of a sequence).
  virtual const SimGroundTruth& groundTruth() const = 0;
  // Ground truth of camera `camera` (index into cameras()) for image `frame`
  // of a sequence (the sensor moved as SimConfig::motion says); points in that
  // camera's frame at that time. Computed on each call (tens of ms).
  virtual SimGroundTruth groundTruthAt(int camera, int frame) const = 0;
  virtual const SimConfig& config() const = 0;

  // Moves the whole sensor, as a robot arm carrying it would: from the next
  // image rendered on, image i of every sequence is seen from
  // base * motion.poseAt(i) (sensor frame, i.e. the first camera's, in the
  // scene's frame; mm), instead of SimConfig::motion from the configured
  // pose. groundTruthAt() follows; groundTruth() stays at the configured
  // pose, and defocus keeps the depths of the configured view (a sensor
  // moving along a wall keeps its distance). Thread-safe.
  virtual void setMotion(const Eigen::Isometry3d& base, const SimMotion& motion) = 0;

  // Renders frame `frame` of pattern `pattern_name` with noise drawn from
  // `noise_seed`: deterministic, for tests. The live camera uses the same path.
  // Throws std::invalid_argument on an unknown pattern, std::out_of_range on
  // a frame outside [0, frame count).
  virtual cv::Mat render(const std::string& pattern_name, int frame,
                         std::uint64_t noise_seed) const = 0;
  // The same for camera `camera` (index into cameras()).
  virtual cv::Mat render(int camera, const std::string& pattern_name, int frame,
                         std::uint64_t noise_seed) const = 0;

  virtual SimCounters counters() const = 0;
  virtual SimSignalCacheStats signalCacheStats() const = 0;
};

}  // namespace sl::drivers
