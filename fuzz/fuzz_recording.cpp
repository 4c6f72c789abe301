// The recording loader (replay): a set folder's meta.yml (OpenCV FileStorage)
// and its PNG frames. The first byte picks what is fuzzed: 0 the meta.yml
// (frames cam_00..03.png are valid 8-bit 4x3 images), 1 the PNG of a set
// whose meta.yml names one 8-bit frame. Every problem must be a
// std::runtime_error naming the file; no frame outside the set folder is
// ever read.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "fuzz_support.h"
#include "sl/drivers/recording.h"

namespace {

const std::filesystem::path& setDir() {
  static const std::filesystem::path dir = [] {
    const auto d = sl::fuzz::scratchDir() / "set_000001";
    std::filesystem::create_directories(d);
    const cv::Mat frame(3, 4, CV_8UC1, cv::Scalar(7));
    for (int i = 0; i < 4; ++i)
      cv::imwrite((d / ("cam_0" + std::to_string(i) + ".png")).string(), frame);
    return d;
  }();
  return dir;
}

const char* kOneFrameMeta =
    "%YAML:1.0\n---\nsequence_id: \"1\"\npattern: p\ntrigger_stamp_ns: \"5\"\ncameras:\n"
    "  - { id: png, bit_depth: 8, frame_count: 1, stamps_ns: [ \"5\" ] }\n";

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const auto& dir = setDir();
  {
    std::ofstream meta(dir / "meta.yml", std::ios::binary | std::ios::trunc);
    if (data[0] % 2 == 0)
      meta.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
    else
      meta << kOneFrameMeta;
  }
  if (data[0] % 2 == 1) {
    std::ofstream png(dir / "png_00.png", std::ios::binary | std::ios::trunc);
    png.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
  }
  try {
    const auto set = sl::drivers::readRecordedSet(dir.string(), true);
    for (const auto& camera : set.cameras)
      if (camera.frames.size() != camera.stamps_ns.size()) __builtin_trap();
  } catch (const std::runtime_error&) {
  }
  return 0;
}
