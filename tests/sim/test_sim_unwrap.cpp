// Temporal unwrapping against the simulator's ground truth where the fringe
// modulation is low: the decoder's default thresholds (codec.h) must keep
// wrong fringe orders (points off by a whole period, ~35 mm here) out of the
// cloud, and the thresholds they replace must not (else the scene would not
// test anything).
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "sl/drivers/sim.h"
#include "sl/pipeline/decoder.h"
#include "sl/pipeline/triangulator.h"
#include "support/sim_rig.h"

namespace {

struct Outcome {
  long long delivered = 0;  // valid points on lit pixels
  long long wrong = 0;      // of those, |z - truth| > kWrongMm
  long long pixels = 0;     // lit pixels
};

// One fine period is ~35 mm of depth at 500 mm; noise is ~0.2 mm here.
constexpr double kWrongMm = 5.0;

Outcome scanAndCompare(const sl::drivers::SimulatedSensor& sensor,
                       const sl::pipeline::PatternSpec& spec,
                       const sl::pipeline::DecoderOptions& options, int scans) {
  const sl::pipeline::Decoder decoder(spec, options);
  sl::pipeline::TriangulatorOptions t;
  t.use = sl::pipeline::TriangulatorOptions::Use::kColumns;
  const sl::pipeline::Triangulator triangulator(sensor.config().rig, t);
  const cv::Mat& truth = sensor.groundTruth().depth_mm;
  const cv::Mat& lit = sensor.groundTruth().lit;
  Outcome o;
  for (int k = 0; k < scans; ++k) {
    std::vector<cv::Mat> frames;
    for (int i = 0; i < spec.frameCount(); ++i)
      frames.push_back(sensor.render(spec.name, i, 7000 + 100 * k + i));
    const sl::pipeline::PointCloud cloud = triangulator.triangulate(decoder.decode(frames, 8));
    for (int r = 0; r < truth.rows; ++r)
      for (int c = 0; c < truth.cols; ++c) {
        if (!lit.at<std::uint8_t>(r, c)) continue;
        ++o.pixels;
        const float z = cloud.points[static_cast<std::size_t>(r) * cloud.width + c].z;
        if (std::isnan(z)) continue;
        ++o.delivered;
        if (std::abs(double(z) - truth.at<float>(r, c)) > kWrongMm) ++o.wrong;
      }
  }
  return o;
}

}  // namespace

TEST_CASE("dim wall: the default decoder thresholds deliver no wrong fringe order",
          "[sim][unwrap]") {
  // 40:1 3+3 (config/sim.yaml) on a dark matte wall at 500 mm: albedo 0.25
  // gives B of ~15-30 DN over the image (A ~ 18-32 DN), where the
  // unit-frequency cue's noise times 40 reaches half a period now and then.
  sl::drivers::SimConfig c = sl::test::simConfig33("3+3_horizontal", 40);
  c.scene.planes = {sl::drivers::SimPlane{{0, 0, 500}, {0, 0, -1}, 0.25}};
  const auto sensor = sl::drivers::SimulatedSensor::create(c);
  const sl::pipeline::PatternSpec spec = c.patterns.front();
  constexpr int kScans = 3;

  const Outcome now = scanAndCompare(*sensor, spec, sl::pipeline::DecoderOptions{}, kScans);
  INFO("defaults: " << now.delivered << " of " << now.pixels << " lit pixels delivered, "
                    << now.wrong << " off by > " << kWrongMm << " mm");
  CHECK(now.wrong == 0);
  // The thresholds cost dim pixels, not the scene: most of the wall stays.
  CHECK(now.delivered > now.pixels / 2);

  // The former defaults (8 DN, 0.35 periods) let wrong orders through here.
  sl::pipeline::DecoderOptions loose;
  loose.min_modulation = 8;
  loose.max_unwrap_error = 0.35f;
  const Outcome before = scanAndCompare(*sensor, spec, loose, kScans);
  INFO("8 DN / 0.35: " << before.delivered << " delivered, " << before.wrong << " wrong");
  CHECK(before.wrong > 20);
  CHECK(before.delivered > now.delivered);
}
