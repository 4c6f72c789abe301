#include "sl_process/process.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <limits>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/frame_files.h"
#include "common/ply.h"
#include "sl/files/pattern_config.h"
#include "sl/drivers/recording.h"

namespace sl::tools {

namespace fs = std::filesystem;

std::vector<std::string> listImages(const std::string& dir) { return listFrameFiles(dir); }

LoadedFrames loadFrames(const std::vector<std::string>& paths) {
  LoadedFrames out;
  for (const std::string& path : paths) {
    cv::Mat image = cv::imread(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
    if (image.empty()) throw std::runtime_error(path + ": cannot read image");
    if (image.channels() == 3) cv::cvtColor(image, image, cv::COLOR_BGR2GRAY);
    if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2GRAY);
    if (image.type() != CV_8UC1 && image.type() != CV_16UC1)
      throw std::runtime_error(path + ": only 8- or 16-bit images are supported");
    if (!out.frames.empty() && (image.size() != out.frames[0].size() ||
                                image.type() != out.frames[0].type()))
      throw std::runtime_error(path + ": size or depth differs from " + paths.front());
    out.frames.push_back(image);
  }
  if (!out.frames.empty()) out.bit_depth = out.frames[0].type() == CV_8UC1 ? 8 : 16;
  return out;
}

void checkPatternFitsCalibration(const pipeline::PatternSpec& pattern,
                                 const pipeline::CameraProjectorCalibration& calibration) {
  if (pattern.projector_width != calibration.projector.width ||
      pattern.projector_height != calibration.projector.height)
    throw std::invalid_argument(
        "pattern '" + pattern.name + "' is for a " + std::to_string(pattern.projector_width) +
        "x" + std::to_string(pattern.projector_height) + " projector, the calibration's is " +
        std::to_string(calibration.projector.width) + "x" +
        std::to_string(calibration.projector.height) +
        " (set the pattern's projector: {width, height} to the calibrated resolution)");
}

bool checkRecordedSet(const pipeline::PatternSpec& pattern, const std::string& pattern_path,
                      const std::string& images_dir) {
  const fs::path meta = fs::path(images_dir) / "meta.yml";
  if (!fs::exists(meta)) return false;
  const pipeline::ImageSet set = drivers::readRecordedSet(images_dir, /*load_images=*/false);
  if (set.pattern_name != pattern.name)
    throw RecordingMismatch(meta.string() + " says the set was recorded with pattern '" +
                            set.pattern_name + "', the pattern file " + pattern_path +
                            " describes '" + pattern.name +
                            "': give the pattern file of the recorded sequence");
  for (const pipeline::CameraImages& camera : set.cameras) {
    if (static_cast<int>(camera.stamps_ns.size()) != pattern.frameCount())
      throw RecordingMismatch(meta.string() + " says camera '" + camera.camera_id + "' recorded " +
                              std::to_string(camera.stamps_ns.size()) + " frames of pattern '" +
                              set.pattern_name + "', the pattern file " + pattern_path +
                              " describes " + std::to_string(pattern.frameCount()));
  }
  const fs::path described = fs::path(images_dir) / drivers::kRecordedPatternFile;
  if (fs::exists(described)) {
    const pipeline::PatternSpec recorded = files::loadPattern(described.string());
    const std::vector<std::string> differences = files::patternDifferences(recorded, pattern);
    if (!differences.empty()) {
      std::string list;
      for (const std::string& d : differences) list += "\n  " + d;
      throw RecordingMismatch(
          described.string() + " describes the recorded pattern '" + recorded.name +
          "' otherwise than the pattern file " + pattern_path + " ('" + pattern.name +
          "'), recorded vs given:" + list +
          "\n  give the pattern file of the recorded sequence (" + described.string() +
          " is one)");
    }
  }
  return true;
}

pipeline::ProjectorMaps decodeCapture(const pipeline::PatternSpec& pattern,
                                      const LoadedFrames& frames,
                                      const pipeline::DecoderOptions& decoder,
                                      pipeline::DecodeHealth* health) {
  if (frames.frames.empty()) throw std::invalid_argument("no frames");
  const auto codec = pipeline::makeCodec(pattern, decoder);
  pipeline::ProjectorMaps maps = codec->decode(frames.frames, frames.bit_depth);
  if (health)
    *health = pipeline::measureDecodeHealth(pattern, codec->options(), maps, frames.frames,
                                            frames.bit_depth);
  return maps;
}

void smoothProjectorCoordinates(pipeline::ProjectorMaps& maps, double sigma_px) {
  if (!(sigma_px > 0)) return;
  const cv::Mat valid = maps.status == 0;
  cv::Mat weight;
  valid.convertTo(weight, CV_32FC1, 1.0 / 255.0);
  cv::Mat weight_sum;
  cv::GaussianBlur(weight, weight_sum, cv::Size(), sigma_px, sigma_px, cv::BORDER_CONSTANT);
  for (cv::Mat* coord : {&maps.up, &maps.vp}) {
    if (coord->empty() || cv::countNonZero(*coord == *coord) == 0) continue;  // axis not encoded
    cv::Mat values = coord->clone();
    values.setTo(0.0f, ~valid);
    cv::Mat sum;
    cv::GaussianBlur(values, sum, cv::Size(), sigma_px, sigma_px, cv::BORDER_CONSTANT);
    cv::Mat smoothed = sum / weight_sum;
    smoothed.copyTo(*coord, valid);
  }
}

PhaseMaps phaseMaps(const pipeline::PatternSpec& pattern, const cv::Mat& coordinate,
                    bool columns) {
  const int axis = pattern.axisLength(columns);
  const double period = pattern.finestPeriod(axis);
  if (!(period > 0))
    throw std::invalid_argument("pattern '" + pattern.name +
                                "' has no sinusoid: no phase to write");
  const double origin = pattern.family == pipeline::PatternFamily::kGrayPhaseShift ? -0.5 : 0.0;
  PhaseMaps out;
  out.absolute.create(coordinate.size(), CV_32FC1);
  out.wrapped.create(coordinate.size(), CV_32FC1);
  const double two_pi = 2.0 * 3.14159265358979323846;
  for (int v = 0; v < coordinate.rows; ++v) {
    const float* p = coordinate.ptr<float>(v);
    float* a = out.absolute.ptr<float>(v);
    float* w = out.wrapped.ptr<float>(v);
    for (int u = 0; u < coordinate.cols; ++u) {
      const double phi = two_pi * (p[u] - origin) / period;
      a[u] = static_cast<float>(phi);
      w[u] = static_cast<float>(phi - two_pi * std::floor(phi / two_pi));
    }
  }
  return out;
}

ProcessResult processCapture(const pipeline::PatternSpec& pattern,
                             const pipeline::CameraProjectorCalibration& calibration,
                             const LoadedFrames& frames, const pipeline::DecoderOptions& decoder,
                             const pipeline::TriangulatorOptions& triangulator,
                             bool undistort_images, double smooth_sigma_px) {
  if (frames.frames.empty()) throw std::invalid_argument("no frames");
  const cv::Size size = frames.frames[0].size();
  if (size.width != calibration.camera.width || size.height != calibration.camera.height)
    throw std::invalid_argument("images are " + std::to_string(size.width) + "x" +
                                std::to_string(size.height) + ", the calibrated camera is " +
                                std::to_string(calibration.camera.width) + "x" +
                                std::to_string(calibration.camera.height));
  checkPatternFitsCalibration(pattern, calibration);
  const auto codec = pipeline::makeCodec(pattern, decoder);
  ProcessResult r;
  if (undistort_images && calibration.camera.hasDistortion()) {
    const pipeline::PinholeModel& cam = calibration.camera;
    // Source pixel (distorted) of every ideal pixel.
    cv::Mat map_x(size, CV_32FC1), map_y(size, CV_32FC1);
    for (int v = 0; v < size.height; ++v) {
      for (int u = 0; u < size.width; ++u) {
        const Eigen::Vector2d xn((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy);
        const Eigen::Vector2d q = cam.normalizedToPixel(xn);
        map_x.at<float>(v, u) = static_cast<float>(q.x());
        map_y.at<float>(v, u) = static_cast<float>(q.y());
      }
    }
    std::vector<cv::Mat> ideal(frames.frames.size());
    for (std::size_t i = 0; i < ideal.size(); ++i)
      cv::remap(frames.frames[i], ideal[i], map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    pipeline::CameraProjectorCalibration pinhole = calibration;
    pinhole.camera.distortion = {0, 0, 0, 0, 0};
    r.maps = codec->decode(ideal, frames.bit_depth);
    r.health =
        pipeline::measureDecodeHealth(pattern, codec->options(), r.maps, ideal, frames.bit_depth);
    pipeline::addEpipolarCheck(r.health, r.maps, pinhole,
                               triangulator.projector_distortion_iterations > 0);
    smoothProjectorCoordinates(r.maps, smooth_sigma_px);
    r.cloud = pipeline::Triangulator(pinhole, triangulator).triangulate(r.maps);
    return r;
  }
  r.maps = codec->decode(frames.frames, frames.bit_depth);
  r.health = pipeline::measureDecodeHealth(pattern, codec->options(), r.maps, frames.frames,
                                           frames.bit_depth);
  pipeline::addEpipolarCheck(r.health, r.maps, calibration,
                             triangulator.projector_distortion_iterations > 0);
  smoothProjectorCoordinates(r.maps, smooth_sigma_px);
  r.cloud = pipeline::Triangulator(calibration, triangulator).triangulate(r.maps);
  return r;
}

namespace {

void write(const std::string& path, const cv::Mat& image) {
  if (!cv::imwrite(path, image)) throw std::runtime_error(path + ": cannot write");
}

}  // namespace

void addPointQuality(ProcessResult& result, const pipeline::PatternSpec& pattern,
                     const pipeline::CameraProjectorCalibration& calibration,
                     const pipeline::CameraNoise& noise, pipeline::TriangulatorOptions::Use use,
                     int normal_step, float max_jump_mm) {
  if (result.cloud.width == 0 || result.cloud.height == 0)
    throw std::invalid_argument("point quality needs a triangulated cloud (--calibration)");
  result.depth_sigma =
      pipeline::depthSigma(result.maps, result.cloud, calibration, pattern, noise, use);
  result.normals = pipeline::organizedNormals(result.cloud, normal_step, max_jump_mm);
}

std::size_t writeOutputs(const ProcessResult& result, int bit_depth, const std::string& out_dir,
                         const pipeline::PatternSpec* pattern) {
  fs::create_directories(out_dir);
  const fs::path dir(out_dir);
  write((dir / "up.tiff").string(), result.maps.up);
  write((dir / "vp.tiff").string(), result.maps.vp);
  write((dir / "modulation.tiff").string(), result.maps.modulation);
  write((dir / "offset.tiff").string(), result.maps.offset);
  write((dir / "status.png").string(), result.maps.status);
  cv::Mat modulation_preview;
  result.maps.modulation.convertTo(modulation_preview, CV_8UC1, std::ldexp(1.0, 8 - bit_depth));
  write((dir / "modulation.png").string(), modulation_preview);
  if (pattern) {
    for (bool columns : {true, false}) {
      const pipeline::Direction skip =
          columns ? pipeline::Direction::kVertical : pipeline::Direction::kHorizontal;
      if (pattern->direction == skip) continue;
      const PhaseMaps phase = phaseMaps(*pattern, columns ? result.maps.up : result.maps.vp,
                                        columns);
      const std::string axis = columns ? "u" : "v";
      write((dir / ("phase_" + axis + "_absolute.tiff")).string(), phase.absolute);
      write((dir / ("phase_" + axis + "_wrapped.tiff")).string(), phase.wrapped);
    }
  }
  const pipeline::PointCloud& cloud = result.cloud;
  if (cloud.width == 0 || cloud.height == 0) return 0;  // maps only
  cv::Mat depth(cloud.height, cloud.width, CV_32FC1);
  std::vector<float> finite;
  for (int v = 0; v < cloud.height; ++v) {
    for (int u = 0; u < cloud.width; ++u) {
      const float z = cloud.points[static_cast<std::size_t>(v) * cloud.width + u].z;
      depth.at<float>(v, u) = z;
      if (std::isfinite(z)) finite.push_back(z);
    }
  }
  write((dir / "depth.tiff").string(), depth);
  cv::Mat depth_preview(depth.size(), CV_8UC1, cv::Scalar(0));
  if (!finite.empty()) {
    std::sort(finite.begin(), finite.end());
    const float lo = finite[finite.size() / 100], hi = finite[finite.size() * 99 / 100];
    const float range = std::max(hi - lo, 1e-3f);
    for (int v = 0; v < depth.rows; ++v) {
      for (int u = 0; u < depth.cols; ++u) {
        const float z = depth.at<float>(v, u);
        if (!std::isfinite(z)) continue;
        const float t = std::clamp((hi - z) / range, 0.0f, 1.0f);  // near = bright
        depth_preview.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(30 + 225 * t);
      }
    }
  }
  write((dir / "depth.png").string(), depth_preview);
  if (result.depth_sigma.empty() && result.normals.empty())
    return writePly(cloud, (dir / "cloud.ply").string(), LengthUnit::kMillimetre);
  if (!result.depth_sigma.empty()) write((dir / "depth_sigma.tiff").string(), result.depth_sigma);
  return writePlyWithQuality(cloud, result.depth_sigma, result.normals,
                             (dir / "cloud.ply").string(), LengthUnit::kMillimetre);
}

}  // namespace sl::tools
