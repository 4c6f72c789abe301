#include "sl/pipeline/intensity_transfer.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <opencv2/core.hpp>

#include "parallel_rows.h"

namespace sl::pipeline {

void transferIntensity(PointCloud& cloud, const CameraProjectorCalibration& own,
                       const CameraProjectorCalibration& other,
                       const CameraImages& images) {
  if (images.frames.empty()) throw std::invalid_argument("intensity camera: no frames");
  const cv::Size size = images.frames.front().size();
  if (size.width != other.camera.width || size.height != other.camera.height)
    throw std::invalid_argument("intensity camera '" + images.camera_id + "': images are " +
                                std::to_string(size.width) + "x" + std::to_string(size.height) +
                                ", its calibration " + std::to_string(other.camera.width) + "x" +
                                std::to_string(other.camera.height));
  cv::Mat mean = cv::Mat::zeros(size, CV_32FC1), frame;
  for (const cv::Mat& f : images.frames) {
    f.convertTo(frame, CV_32F);
    mean += frame;
  }
  mean /= double(images.frames.size());

  // own camera -> projector -> other camera.
  const Eigen::Isometry3d own_to_other = cameraToCamera(own, other);
  const Eigen::Matrix3d rotation = own_to_other.linear();
  const Eigen::Vector3d translation = own_to_other.translation();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const int w = size.width, h = size.height;
  parallelRows(cloud.height, [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r) {
      for (int c = 0; c < cloud.width; ++c) {
        pipeline::PointXYZI& p = cloud.points[std::size_t(r) * cloud.width + c];
        if (!std::isfinite(p.z)) continue;
        const Eigen::Vector3d x = rotation * Eigen::Vector3d(p.x, p.y, p.z) + translation;
        p.intensity = nan;
        if (!(x.z() > 0)) continue;
        const Eigen::Vector2d uv = other.camera.project(x);
        // Bilinear between the four pixel centres around (u, v).
        const double u0 = std::floor(uv.x()), v0 = std::floor(uv.y());
        if (!(u0 >= 0 && v0 >= 0 && u0 + 1 < w && v0 + 1 < h)) continue;
        const int iu = int(u0), iv = int(v0);
        const float fu = float(uv.x() - u0), fv = float(uv.y() - v0);
        const float* row0 = mean.ptr<float>(iv);
        const float* row1 = mean.ptr<float>(iv + 1);
        p.intensity = (1 - fv) * ((1 - fu) * row0[iu] + fu * row0[iu + 1]) +
                      fv * ((1 - fu) * row1[iu] + fu * row1[iu + 1]);
      }
    }
  });
}

}  // namespace sl::pipeline
