// PinholeModel: projection and its inverse.
#include <algorithm>
#include <cmath>
#include <vector>

#include <catch2/catch.hpp>

#include "sl/pipeline/camera_model.h"

using sl::pipeline::PinholeModel;

namespace {

PinholeModel realisticCamera() {
  PinholeModel m;
  m.width = 1440;
  m.height = 1080;
  m.fx = 2400;
  m.fy = 2398;
  m.cx = 721.3;
  m.cy = 538.2;
  m.distortion = {-0.1, 0.05, 1e-3, -5e-4, 0.0};
  return m;
}

}  // namespace

TEST_CASE("K and hasDistortion", "[camera_model]") {
  PinholeModel m = realisticCamera();
  const Eigen::Matrix3d k = m.K();
  CHECK(k(0, 0) == m.fx);
  CHECK(k(1, 1) == m.fy);
  CHECK(k(0, 2) == m.cx);
  CHECK(k(1, 2) == m.cy);
  CHECK(k(2, 2) == 1.0);
  CHECK(k(0, 1) == 0.0);
  CHECK(m.hasDistortion());
  m.distortion = {0, 0, 0, 0, 0};
  CHECK_FALSE(m.hasDistortion());
}

TEST_CASE("pixelToNormalized inverts normalizedToPixel across the image", "[camera_model]") {
  const bool distorted = GENERATE(false, true);
  PinholeModel m = realisticCamera();
  if (!distorted) m.distortion = {0, 0, 0, 0, 0};

  // Every 8th pixel plus the last row and column, i.e. the corners, where the
  // distortion is largest (about 25 px for these coefficients).
  auto samples = [](int n) {
    std::vector<int> s;
    for (int i = 0; i < n; i += 8) s.push_back(i);
    if (s.back() != n - 1) s.push_back(n - 1);
    return s;
  };
  double max_error_px = 0;
  double max_shift_px = 0;
  for (int v : samples(m.height)) {
    for (int u : samples(m.width)) {
      const Eigen::Vector2d pixel(u, v);
      const Eigen::Vector2d xn = m.pixelToNormalized(pixel);
      const Eigen::Vector2d back = m.normalizedToPixel(xn);
      max_error_px = std::max(max_error_px, (back - pixel).norm());
      const Eigen::Vector2d pinhole(m.fx * xn.x() + m.cx, m.fy * xn.y() + m.cy);
      max_shift_px = std::max(max_shift_px, (pinhole - pixel).norm());
    }
  }
  CAPTURE(max_error_px, max_shift_px);
  CHECK(max_error_px < 1e-6);
  if (distorted) {
    CHECK(max_shift_px > 10.0);  // the distortion is not negligible
  } else {
    CHECK(max_shift_px < 1e-9);
  }
}

TEST_CASE("project agrees with normalizedToPixel of x/z, y/z", "[camera_model]") {
  const PinholeModel m = realisticCamera();
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0, 0, 500), Eigen::Vector3d(-120, 80, 400),
                                  Eigen::Vector3d(250, -190, 900)}) {
    const Eigen::Vector2d a = m.project(p);
    const Eigen::Vector2d b = m.normalizedToPixel({p.x() / p.z(), p.y() / p.z()});
    CHECK((a - b).norm() < 1e-12);
  }
  // The principal point is the image of the optical axis.
  const Eigen::Vector2d c = m.project({0, 0, 1000});
  CHECK(c.x() == Approx(m.cx).margin(1e-12));
  CHECK(c.y() == Approx(m.cy).margin(1e-12));
}
