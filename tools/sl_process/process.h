// Offline processing of recorded captures (the core of sl_process, also used
// by the tests): read a folder of frames, decode with a pattern's codec,
// triangulate with a calibration, write maps, cloud and previews.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/codec.h"
#include "sl/pipeline/decode_health.h"
#include "sl/pipeline/point_quality.h"
#include "sl/pipeline/triangulator.h"

namespace sl::tools {

// Image files of `dir` in projection order: common/frame_files.h's
// listFrameFiles() (natural order of the numbers in the names; ambiguous
// numbering refused with a message).
std::vector<std::string> listImages(const std::string& dir);

struct LoadedFrames {
  std::vector<cv::Mat> frames;  // CV_8UC1 or CV_16UC1, all one size
  int bit_depth = 8;            // 8 or 16 (the container depth)
};
// Reads the images as single-channel 8- or 16-bit (colour is converted to
// grey). Throws std::runtime_error naming the file on a read error or on
// mixed sizes or depths.
LoadedFrames loadFrames(const std::vector<std::string>& paths);

struct ProcessResult {
  pipeline::ProjectorMaps maps;
  pipeline::PointCloud cloud;  // mm, camera optical frame; empty (0 x 0) for maps only
  pipeline::DecodeHealth health;  // of the decoded frames (measureDecodeHealth)
  // Per-point quality (addPointQuality), empty unless computed: expected
  // depth sigma (CV_32FC1, mm) and unit normals (CV_32FC3), the cloud's size.
  cv::Mat depth_sigma;
  cv::Mat normals;
};

// Throws std::invalid_argument when the pattern was made for another
// projector size than the calibration's projector (its coordinates would be
// scaled wrongly: a wrong cloud or none at all).
void checkPatternFitsCalibration(const pipeline::PatternSpec& pattern,
                                 const pipeline::CameraProjectorCalibration& calibration);

// A recorded set that says it was made with another pattern than the
// pattern file given for it.
struct RecordingMismatch : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// When `images_dir` is a recorded set folder (sl-sensor-recording/1: it holds
// a meta.yml), checks what the recording says against the pattern file
// `pattern_path` describing `pattern`: the pattern name and the frame count
// of every camera (meta.yml), and, when the set keeps the description of its
// pattern (pattern.yml, written by the daemon's recorder), every key of it:
// family, direction, projector, steps, frequencies, unwrapping, Gray bits,
// phase conventions, frame order. Throws RecordingMismatch naming the
// recording's file and the pattern file with both values of every
// difference; returns false (nothing checked) for a plain folder of images.
// (A set recorded before pattern.yml holds the pattern's name only: another
// period under the same name then shows in the decode health.)
bool checkRecordedSet(const pipeline::PatternSpec& pattern, const std::string& pattern_path,
                      const std::string& images_dir);

// Decodes one capture into maps, without triangulating; with `health`, also
// measures the decode health of the maps.
pipeline::ProjectorMaps decodeCapture(const pipeline::PatternSpec& pattern,
                                      const LoadedFrames& frames,
                                      const pipeline::DecoderOptions& decoder,
                                      pipeline::DecodeHealth* health = nullptr);

// Smooths the decoded projector coordinates (up, vp) with a Gaussian of
// `sigma_px` camera px, normalised over the valid pixels only (NaN and
// invalid pixels neither contribute nor receive a value). Meant for noisy
// single-frequency captures (e.g. 3 steps at one period across the
// projector), where the coordinate is the phase scaled and has no period
// jumps to blur across. sigma_px <= 0 leaves the maps as they are.
void smoothProjectorCoordinates(pipeline::ProjectorMaps& maps, double sigma_px);

// Phase maps of the finest sinusoid of the pattern, derived from the decoded
// coordinate of one axis: absolute phase Phi = 2 pi (p - origin) / period
// (rad; origin -0.5 px for Gray + phase shift, else 0) and the wrapped phase
// Phi mod 2 pi in [0, 2 pi). NaN where the coordinate is. Throws
// std::invalid_argument for a pattern without sinusoids (Gray code).
struct PhaseMaps {
  cv::Mat absolute;  // CV_32FC1, rad
  cv::Mat wrapped;   // CV_32FC1, rad
};
PhaseMaps phaseMaps(const pipeline::PatternSpec& pattern, const cv::Mat& coordinate,
                    bool columns);

// Decodes and triangulates one capture; the health includes the epipolar
// check (pipeline::addEpipolarCheck) when both axes are decoded. The camera size of the calibration
// must equal the frames' size, and its projector size the pattern's
// (std::invalid_argument otherwise).
//
// With undistort_images the frames are first resampled (bilinear) onto the
// ideal pinhole camera of the same K, and triangulated with a distortion-free
// camera: maps and cloud are then indexed by undistorted pixels, SLStudio's
// convention (its reference reconstructions are in that grid). Otherwise
// pixels stay in the distorted (raw) image and the triangulator undistorts
// each ray.
ProcessResult processCapture(const pipeline::PatternSpec& pattern,
                             const pipeline::CameraProjectorCalibration& calibration,
                             const LoadedFrames& frames, const pipeline::DecoderOptions& decoder,
                             const pipeline::TriangulatorOptions& triangulator,
                             bool undistort_images = false, double smooth_sigma_px = 0);

// Fills result.depth_sigma (pipeline::depthSigma with `noise` and the axis
// `use` picks) and result.normals (pipeline::organizedNormals, `normal_step`
// px, neighbours farther than max_jump_mm dropped) of a triangulated result.
// `calibration`: the one processCapture triangulated with (its projector and
// R, t are what matter). Throws std::invalid_argument for a result without a
// cloud or a pattern family without a phase-noise model (Gray code, micro
// phase shift).
void addPointQuality(ProcessResult& result, const pipeline::PatternSpec& pattern,
                     const pipeline::CameraProjectorCalibration& calibration,
                     const pipeline::CameraNoise& noise, pipeline::TriangulatorOptions::Use use,
                     int normal_step = 3, float max_jump_mm = 5.0f);

// Writes into `out_dir` (created if missing):
//   up.tiff, vp.tiff, modulation.tiff, offset.tiff, depth.tiff: 32-bit float
//     TIFF (projector px / camera DN / mm), NaN where invalid (depth.tiff,
//     depth.png and cloud.ply only with a cloud)
//   with `pattern` (phase outputs): phase_u_absolute.tiff,
//     phase_u_wrapped.tiff (and phase_v_... for rows) from phaseMaps()
//   status.png: 8-bit PixelStatus per pixel (0 valid, 1 low modulation,
//     2 saturated, 3 unwrap inconsistent, 4 out of range)
//   cloud.ply: binary PLY of the valid points (mm); with point quality
//     (addPointQuality) also nx ny nz and confidence (expected depth sigma,
//     mm) per point, and depth_sigma.tiff (mm)
//   depth.png, modulation.png: 8-bit previews (depth: near bright, invalid
//     black, stretched over the 1st..99th percentile; modulation: 0..255 DN
//     at 8 bits, clipped)
// Returns the number of points written. Throws std::runtime_error on I/O errors.
std::size_t writeOutputs(const ProcessResult& result, int bit_depth, const std::string& out_dir,
                         const pipeline::PatternSpec* pattern = nullptr);

}  // namespace sl::tools
