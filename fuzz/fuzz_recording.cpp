// The recording loader (replay): a set folder's meta.yml (OpenCV FileStorage)
// and its PNG frames, and MCAP files of image sets. The first byte (mod 3)
// picks what is fuzzed: 0 the meta.yml (frames cam_00..03.png are valid
// 8-bit 4x3 images), 1 the PNG of a set whose meta.yml names one 8-bit
// frame, 2 an MCAP file opened and every set loaded. Every problem must be a
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

void fuzzMcap(const std::uint8_t* data, std::size_t size) {
  static const std::string path = (sl::fuzz::scratchDir() / "fuzz.mcap").string();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  try {
    const auto recording = sl::drivers::RecordingReader::open(path);
    for (std::size_t i = 0; i < recording->size(); ++i) {
      const auto set = recording->load(i);
      for (const auto& camera : set.cameras)
        if (camera.frames.size() != camera.stamps_ns.size()) __builtin_trap();
    }
  } catch (const std::runtime_error& e) {
    if (std::string(e.what()).rfind(path + ": ", 0) != 0) __builtin_trap();  // names the file
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  if (data[0] % 3 == 2) {
    fuzzMcap(data + 1, size - 1);
    return 0;
  }
  const auto& dir = setDir();
  {
    std::ofstream meta(dir / "meta.yml", std::ios::binary | std::ios::trunc);
    if (data[0] % 3 == 0)
      meta.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
    else
      meta << kOneFrameMeta;
  }
  if (data[0] % 3 == 1) {
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
