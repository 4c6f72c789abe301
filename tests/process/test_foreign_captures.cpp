// Captures and calibrations from other rigs (issue 15): frame order from
// file names, explicit frame lists, pattern vs calibration projector size,
// maps-only processing and phase outputs, OpenCV FileStorage calibrations
// under their authors' own keys. Real data from SL_SHARED_DATA_DIR is read
// in place (renamed views of it are symlinks, never copies).
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <catch2/catch.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/frame_files.h"
#include "sl/files/calibration_io.h"
#include "sl/daemon/config.h"
#include "sl/files/pattern_config.h"
#include "sl_process/process.h"

namespace fs = std::filesystem;
using namespace sl;

namespace {

const std::string kData = std::string(SL_SHARED_DATA_DIR) + "/slstudio-skull";
const std::string kPatterns = std::string(SL_SOURCE_DIR) + "/config/patterns/";
const std::string kProcess = std::string(SL_BINARY_DIR) + "/tools/sl_process";

fs::path scratch(const std::string& name) {
  const fs::path p = fs::path(SL_BINARY_DIR) / "test_foreign" / name;
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

// `dir`/<names[i]> -> skull_gray frame i (symlinks).
void linkFrames(const fs::path& dir, const std::string& source,
                const std::vector<std::string>& names) {
  for (std::size_t i = 0; i < names.size(); ++i) {
    char original[32];
    std::snprintf(original, sizeof original, "frame_%02zu.png", i);
    fs::create_symlink(fs::path(kData) / source / original, dir / names[i]);
  }
}

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

int run(const std::string& command) {
  const int rc = std::system((command + " > /dev/null 2>&1").c_str());
  return WEXITSTATUS(rc);
}

std::string stderrOf(const std::string& command, const fs::path& file) {
  std::system((command + " > /dev/null 2> " + file.string()).c_str());
  std::ifstream in(file);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

long differing(const cv::Mat& a, const cv::Mat& b) {
  long n = 0;
  for (int v = 0; v < a.rows; ++v)
    for (int u = 0; u < a.cols; ++u) {
      const float x = a.at<float>(v, u), y = b.at<float>(v, u);
      n += !(std::isnan(x) && std::isnan(y)) && !(std::abs(x - y) <= 1e-3f);
    }
  return n;
}

}  // namespace

TEST_CASE("numbered file names without padding decode in numeric order", "[process][order]") {
  CHECK(tools::naturalLess("x_2.png", "x_10.png"));
  CHECK_FALSE(tools::naturalLess("x_10.png", "x_2.png"));
  CHECK(tools::naturalLess("pose2_frame10", "pose10_frame1"));
  const fs::path dir = scratch("unpadded");
  std::vector<std::string> names;
  for (int i = 1; i <= 12; ++i) names.push_back("g_" + std::to_string(i) + ".png");
  linkFrames(dir, "skull_gray", names);
  const auto files = tools::listImages(dir.string());
  REQUIRE(files.size() == 12);
  for (int i = 0; i < 12; ++i) CHECK(fs::path(files[i]).filename() == names[i]);

  const auto pattern = files::loadPattern(kPatterns + "slstudio_gray.yaml");
  const auto reference =
      tools::decodeCapture(pattern, tools::loadFrames(tools::listImages(kData + "/skull_gray")), {});
  const auto renamed = tools::decodeCapture(pattern, tools::loadFrames(files), {});
  CHECK(differing(reference.up, renamed.up) == 0);
  // What sorting the names as strings did (g_1, g_10, g_11, g_12, g_2, ...):
  // most decoded pixels wrong. The test above can fail.
  std::vector<std::string> lexical = files;
  std::sort(lexical.begin(), lexical.end());
  const auto wrong = tools::decodeCapture(pattern, tools::loadFrames(lexical), {});
  CHECK(differing(reference.up, wrong.up) > cv::countNonZero(reference.status == 0) / 2);
}

TEST_CASE("ambiguous numbering is refused and asks for a list", "[process][order]") {
  const fs::path twice = scratch("same_number");
  linkFrames(twice, "skull_2x3", {"x_1.png", "x_01.png", "x_2.png", "x_3.png", "x_4.png", "x_5.png"});
  const std::string e = errorOf([&] { tools::listImages(twice.string()); });
  CHECK(e.find("x_01.png") != std::string::npos);
  CHECK(e.find("--list") != std::string::npos);
  const fs::path mixed = scratch("mixed_names");
  linkFrames(mixed, "skull_2x3", {"white.png", "black.png", "f_0.png", "f_1.png", "f_2.png", "f_3.png"});
  const std::string m = errorOf([&] { tools::listImages(mixed.string()); });
  CHECK(m.find("no single numbering") != std::string::npos);
  // sl_process refuses with rc 1; with an explicit list it runs.
  const std::string base = kProcess + " --pattern " + kPatterns + "slstudio_2x3.yaml --images " +
                           mixed.string() + " --out " + scratch("mixed_out").string();
  CHECK(run(base) == 1);
  {
    std::ofstream list(mixed / "order.txt");
    list << "# projection order\nwhite.png\nblack.png\nf_0.png\nf_1.png\nf_2.png\nf_3.png\n";
  }
  CHECK(run(base + " --list " + (mixed / "order.txt").string()) == 0);
  // A list is checked: missing files and duplicates name the line.
  {
    std::ofstream list(mixed / "bad.txt");
    list << "white.png\nblack.png\nf_0.png\nf_1.png\nf_1.png\nf_3.png\n";
  }
  const std::string dup = errorOf([&] { tools::readFrameList((mixed / "bad.txt").string(), mixed.string()); });
  CHECK(dup.find("bad.txt:5") != std::string::npos);
  CHECK(dup.find("twice") != std::string::npos);
  {
    std::ofstream list(mixed / "missing.txt");
    list << "white.png\nnot_there.png\n";
  }
  CHECK(errorOf([&] { tools::readFrameList((mixed / "missing.txt").string(), mixed.string()); })
            .find("missing.txt:2") != std::string::npos);
}

TEST_CASE("a pattern for another projector size than the calibration's is refused",
          "[process][projector]") {
  const fs::path dir = scratch("projector_size");
  {
    std::ofstream p(dir / "p.yaml");
    p << "name: wrong_projector\nfamily: phase_shift\ndirection: horizontal\n"
         "projector: {width: 1920, height: 1080}\nsteps: 3\nfrequencies: [16, 1]\n";
  }
  const std::string command = kProcess + " --pattern " + (dir / "p.yaml").string() +
                              " --calibration " + kData + "/calibration.xml --images " + kData +
                              "/skull_2x3 --out " + (dir / "out").string();
  const std::string message = stderrOf(command, dir / "stderr.txt");
  CHECK(message.find("1920x1080") != std::string::npos);
  CHECK(message.find("1824x1140") != std::string::npos);
  CHECK(run(command) == 1);
  CHECK_FALSE(fs::exists(dir / "out" / "cloud.ply"));
}

TEST_CASE("maps and phase without a calibration", "[process][phase]") {
  const fs::path out = scratch("maps_only");
  REQUIRE(run(kProcess + " --pattern " + kPatterns + "slstudio_2x3.yaml --images " + kData +
              "/skull_2x3 --phase --out " + out.string()) == 0);
  for (const char* f : {"up.tiff", "vp.tiff", "status.png", "phase_u_absolute.tiff",
                        "phase_u_wrapped.tiff"})
    CHECK(fs::exists(out / f));
  CHECK_FALSE(fs::exists(out / "cloud.ply"));
  CHECK_FALSE(fs::exists(out / "phase_v_wrapped.tiff"));
  // The wrapped phase is SLStudio's (README of the data): atan2(sqrt(3)
  // (I2 - I3), 2 I1 - I2 - I3) of the fine set, mod 2 pi; the absolute phase
  // unwraps it (a multiple of 2 pi away).
  const cv::Mat wrapped = cv::imread((out / "phase_u_wrapped.tiff").string(), cv::IMREAD_UNCHANGED);
  const cv::Mat absolute = cv::imread((out / "phase_u_absolute.tiff").string(), cv::IMREAD_UNCHANGED);
  const cv::Mat status = cv::imread((out / "status.png").string(), cv::IMREAD_UNCHANGED);
  std::vector<cv::Mat> I;
  for (int i = 0; i < 3; ++i)
    I.push_back(cv::imread(kData + "/skull_2x3/frame_0" + std::to_string(i) + ".png",
                           cv::IMREAD_GRAYSCALE));
  long valid = 0, agree = 0, integer_periods = 0;
  const double two_pi = 2 * CV_PI;
  for (int v = 0; v < status.rows; v += 3)
    for (int u = 0; u < status.cols; u += 3) {
      if (status.at<std::uint8_t>(v, u) != 0) continue;
      ++valid;
      const double i1 = I[0].at<std::uint8_t>(v, u), i2 = I[1].at<std::uint8_t>(v, u),
                   i3 = I[2].at<std::uint8_t>(v, u);
      double ref = std::atan2(std::sqrt(3.0) * (i2 - i3), 2 * i1 - i2 - i3);
      if (ref < 0) ref += two_pi;
      const double w = wrapped.at<float>(v, u);
      const double d = std::remainder(w - ref, two_pi);
      agree += std::abs(d) < 2e-3;
      const double k = (absolute.at<float>(v, u) - w) / two_pi;
      integer_periods += std::abs(k - std::round(k)) < 1e-3 && w >= 0 && w < two_pi;
    }
  REQUIRE(valid > 5000);
  CHECK(double(agree) / valid > 0.999);
  CHECK(integer_periods == valid);
  // A Gray code has no phase to write: refused, not an empty file.
  CHECK(run(kProcess + " --pattern " + kPatterns + "slstudio_gray.yaml --images " + kData +
            "/skull_gray --phase --out " + scratch("gray_phase").string()) == 1);
}

TEST_CASE("an OpenCV FileStorage calibration under its author's keys", "[process][calibration]") {
  const auto xml = files::loadCalibration(kData + "/calibration.xml");
  const auto& c = xml.calibration;
  const fs::path dir = scratch("opencv_keys");
  for (const char* ext : {".yml", ".xml", ".json"}) {
    // Another tool's layout: 8 distortion terms, the pose projector -> camera
    // as a Rodrigues vector, metres, no projector size.
    const std::string file = (dir / (std::string("stereo") + ext)).string();
    {
      cv::FileStorage fs(file, cv::FileStorage::WRITE);
      auto K = [](const pipeline::PinholeModel& m) {
        return cv::Mat((cv::Mat_<double>(3, 3) << m.fx, 0, m.cx, 0, m.fy, m.cy, 0, 0, 1));
      };
      cv::Mat d1 = cv::Mat::zeros(1, 8, CV_64F), d2(5, 1, CV_64F);
      for (int i = 0; i < 5; ++i) {
        d1.at<double>(i) = c.camera.distortion[i];
        d2.at<double>(i) = c.projector.distortion[i];
      }
      cv::Mat R(3, 3, CV_64F), t(3, 1, CV_64F);
      const Eigen::Matrix3d Rinv = c.R.transpose();
      const Eigen::Vector3d tinv = -Rinv * c.t / 1000.0;
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) R.at<double>(i, j) = Rinv(i, j);
        t.at<double>(i) = tinv(i);
      }
      cv::Mat rvec;
      cv::Rodrigues(R, rvec);
      fs << "image_width" << c.camera.width << "image_height" << c.camera.height;
      fs << "camera_matrix" << K(c.camera) << "dist_coeffs" << d1;
      fs << "proj_K" << K(c.projector) << "proj_dist" << d2;
      fs << "om" << rvec << "T" << t;
    }
    const std::string keys = (dir / "keys.yaml").string();
    {
      std::ofstream k(keys);
      k << "camera: {matrix: camera_matrix, distortion: dist_coeffs, width: image_width, "
           "height: image_height}\nprojector: {matrix: proj_K, distortion: proj_dist, width: 1824, "
           "height: 1140}\nrotation: om\ntranslation: T\npose: projector_to_camera\n"
           "translation_unit: m\n";
    }
    CAPTURE(ext);
    const auto imported =
        files::loadOpenCvCalibration(file, files::parseOpenCvCalibrationKeys(keys)).calibration;
    CHECK(imported.camera.width == 1688);
    CHECK(imported.projector.width == 1824);
    CHECK(imported.camera.fx == Approx(c.camera.fx));
    CHECK(imported.projector.cy == Approx(c.projector.cy));
    CHECK(imported.camera.distortion[4] == Approx(c.camera.distortion[4]));
    CHECK((imported.R - c.R).norm() < 1e-6);  // the XML stores float: R re-orthonormalised
    CHECK((imported.t - c.t).norm() < 1e-4);
    // The same through sl_process with an inline mapping: same points.
    const std::string inline_keys =
        "camera.matrix=camera_matrix,camera.distortion=dist_coeffs,camera.width=image_width,"
        "camera.height=image_height,projector.matrix=proj_K,projector.distortion=proj_dist,"
        "projector.width=1824,projector.height=1140,rotation=om,translation=T,"
        "pose=projector_to_camera,translation_unit=m";
    const fs::path a = dir / "out_keys", b = dir / "out_xml";
    const std::string common = " --pattern " + kPatterns + "slstudio_2x3.yaml --images " + kData +
                               "/skull_2x3 --min-modulation 18.3 --projector-iterations 0 ";
    REQUIRE(run(kProcess + common + "--calibration " + file + " --calibration-keys " + inline_keys +
                " --out " + a.string()) == 0);
    REQUIRE(run(kProcess + common + "--calibration " + kData + "/calibration.xml --out " +
                b.string()) == 0);
    CHECK(fs::file_size(a / "cloud.ply") == fs::file_size(b / "cloud.ply"));
    const cv::Mat za = cv::imread((a / "depth.tiff").string(), cv::IMREAD_UNCHANGED);
    const cv::Mat zb = cv::imread((b / "depth.tiff").string(), cv::IMREAD_UNCHANGED);
    CHECK(differing(za, zb) == 0);
  }
  // Mistakes name the file and the key.
  const std::string file = (dir / "stereo.yml").string();
  CHECK(errorOf([&] {
          files::loadOpenCvCalibration(
              file, files::parseOpenCvCalibrationKeys(
                        "camera.matrix=K1,camera.distortion=dist_coeffs,camera.width=image_width,"
                        "camera.height=image_height,projector.matrix=proj_K,"
                        "projector.distortion=proj_dist,projector.width=1824,"
                        "projector.height=1140,rotation=om,translation=T"));
        }).find("key 'K1' missing") != std::string::npos);
  CHECK(errorOf([&] {
          files::parseOpenCvCalibrationKeys("camera.matrix=K1,rotation=om");
        }).find("lacks 'camera.distortion'") != std::string::npos);
  CHECK(errorOf([&] {
          files::loadOpenCvCalibration(
              file, files::parseOpenCvCalibrationKeys(
                        "camera.matrix=camera_matrix,camera.distortion=dist_coeffs,"
                        "camera.width=image_width,camera.height=image_height,"
                        "projector.matrix=proj_K,projector.distortion=proj_dist,"
                        "projector.width=screen_w,projector.height=1140,rotation=om,translation=T"));
        }).find("give the size as a number") != std::string::npos);
}

TEST_CASE("the daemon's calibration: reads a foreign OpenCV file through a key mapping",
          "[process][calibration][daemon]") {
  std::ifstream in(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const daemon::DaemonConfig sim = daemon::parseConfig(text, std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  const auto& rig = sim.calibration;
  const fs::path dir = scratch("daemon_keys");
  const std::string file = (dir / "rig.yml").string();
  {
    cv::FileStorage fs(file, cv::FileStorage::WRITE);
    auto K = [](const pipeline::PinholeModel& m) {
      return cv::Mat((cv::Mat_<double>(3, 3) << m.fx, 0, m.cx, 0, m.fy, m.cy, 0, 0, 1));
    };
    auto D = [](const pipeline::PinholeModel& m) {
      cv::Mat d(1, 5, CV_64F);
      for (int i = 0; i < 5; ++i) d.at<double>(i) = m.distortion[i];
      return d;
    };
    cv::Mat R(3, 3, CV_64F), t(3, 1, CV_64F);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) R.at<double>(i, j) = rig.R(i, j);
      t.at<double>(i) = rig.t(i);
    }
    fs << "K1" << K(rig.camera) << "D1" << D(rig.camera) << "K2" << K(rig.projector) << "D2"
       << D(rig.projector) << "R" << R << "T" << t;
  }
  const std::string block =
      "calibration:\n  file: " + file +
      "\n  keys:\n    camera: {matrix: K1, distortion: D1, width: " +
      std::to_string(rig.camera.width) + ", height: " + std::to_string(rig.camera.height) +
      "}\n    projector: {matrix: K2, distortion: D2, width: " + std::to_string(rig.projector.width) +
      ", height: " + std::to_string(rig.projector.height) + "}\n    rotation: R\n    translation: T\n";
  const auto at = text.find("calibration: sim");
  REQUIRE(at != std::string::npos);
  std::string changed = text;
  changed.replace(at, changed.find('\n', at) - at, block);
  const daemon::DaemonConfig config =
      daemon::parseConfig(changed, std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  CHECK(config.calibration.camera.fx == Approx(rig.camera.fx));
  CHECK(config.calibration.projector.width == rig.projector.width);
  CHECK((config.calibration.R - rig.R).norm() < 1e-12);
  CHECK((config.calibration.t - rig.t).norm() < 1e-9);
  // Without keys: refused, naming the key.
  std::string no_keys = text;
  no_keys.replace(at, no_keys.find('\n', at) - at, "calibration: {file: " + file + "}");
  CHECK(errorOf([&] { daemon::parseConfig(no_keys, "test.yaml"); }).find("keys") !=
        std::string::npos);
}

TEST_CASE("phase smoothing of a single-frequency 3-step capture", "[process][smoothing]") {
  // The unit-frequency frames of skull_2x3 alone are a single-frequency
  // 3-step capture. Against the 3+3 decode of all six frames (40 x less
  // phase noise) it differs by its noise and by a smooth systematic error
  // (the projector's non-linearity on the unit-frequency phase); the noise
  // is what smoothing removes: measured as the difference minus its own
  // local mean (a 6 px Gaussian over the valid pixels).
  const auto p33 = files::loadPattern(kPatterns + "slstudio_2x3.yaml");
  const auto reference =
      tools::decodeCapture(p33, tools::loadFrames(tools::listImages(kData + "/skull_2x3")), {});
  const auto single = files::parsePatternText(
      "name: unit_3step\nfamily: phase_shift\ndirection: horizontal\nsteps: 3\nfrequencies: [1]\n",
      "unit.yaml");
  std::vector<std::string> files;
  for (int i = 3; i < 6; ++i) files.push_back(kData + "/skull_2x3/frame_0" + std::to_string(i) + ".png");
  pipeline::DecoderOptions options;
  options.min_modulation = 18.3f;
  const auto frames = tools::loadFrames(files);
  const auto raw = tools::decodeCapture(single, frames, options);
  auto smoothed = tools::decodeCapture(single, frames, options);
  tools::smoothProjectorCoordinates(smoothed, 2.0);
  // Pixels valid in both, away from invalid ones (the detrending window).
  auto noise = [&](const pipeline::ProjectorMaps& maps, long& invalid_touched) {
    pipeline::ProjectorMaps d;
    d.status = cv::Mat(maps.status.size(), CV_8UC1, cv::Scalar(1));
    d.up = cv::Mat(maps.up.size(), CV_32FC1, cv::Scalar(NAN));
    d.vp = cv::Mat(maps.up.size(), CV_32FC1, cv::Scalar(NAN));
    invalid_touched = 0;
    for (int v = 0; v < maps.up.rows; ++v)
      for (int u = 0; u < maps.up.cols; ++u) {
        if (maps.status.at<std::uint8_t>(v, u) != 0) {
          invalid_touched += !std::isnan(maps.up.at<float>(v, u));
          continue;
        }
        if (reference.status.at<std::uint8_t>(v, u) != 0) continue;
        d.status.at<std::uint8_t>(v, u) = 0;
        d.up.at<float>(v, u) = maps.up.at<float>(v, u) - reference.up.at<float>(v, u);
      }
    pipeline::ProjectorMaps trend = d;
    trend.up = d.up.clone();
    tools::smoothProjectorCoordinates(trend, 6.0);
    const cv::Mat interior = d.status == 0;
    cv::Mat eroded;
    cv::erode(interior, eroded, cv::Mat::ones(25, 25, CV_8UC1));
    double sum2 = 0;
    long n = 0;
    for (int v = 0; v < d.up.rows; ++v)
      for (int u = 0; u < d.up.cols; ++u) {
        if (!eroded.at<std::uint8_t>(v, u)) continue;
        const double e = d.up.at<float>(v, u) - trend.up.at<float>(v, u);
        sum2 += e * e;
        ++n;
      }
    REQUIRE(n > 20000);
    return std::sqrt(sum2 / n);
  };
  long raw_touched = 0, smooth_touched = 0;
  const double raw_noise = noise(raw, raw_touched), smooth_noise = noise(smoothed, smooth_touched);
  WARN("single-frequency 3-step on skull_2x3: noise (difference to the 3+3 decode minus its "
       "local mean) "
       << raw_noise << " px raw, " << smooth_noise << " px smoothed (sigma 2 px)");
  CHECK(smooth_noise < 0.5 * raw_noise);
  CHECK(smooth_touched == 0);  // invalid pixels stay NaN
  // sl_process takes it on the command line.
  const fs::path out = scratch("smooth_cli");
  {
    std::ofstream list(out / "unit.txt");
    list << "frame_03.png\nframe_04.png\nframe_05.png\n";
    std::ofstream p(out / "unit.yaml");
    p << "name: unit_3step\nfamily: phase_shift\ndirection: horizontal\nsteps: 3\nfrequencies: [1]\n";
  }
  CHECK(run(kProcess + " --pattern " + (out / "unit.yaml").string() + " --images " + kData +
            "/skull_2x3 --list " + (out / "unit.txt").string() + " --smooth-phase 2 --out " +
            (out / "o").string()) == 0);
  CHECK(fs::exists(out / "o" / "up.tiff"));
}
