// recording_check DIR: reads a recording folder as the replay does
// (drivers::RecordingReader) and loads every set with its frames. Prints
// one line per set folder the reader skips as incomplete ("incomplete:
// <message naming the folder or file>"), "set <folder> <crc32 of its
// frames>" per complete set, then "complete N incomplete M". Exit 0 when
// every listed set loads, 1 (with "refused: <message>") when the reader or
// a set is refused, 2 on usage. For tests/daemon/recording_faults.sh.
#include <cstdio>
#include <exception>
#include <string>

#include <zlib.h>

#include "sl/drivers/recording.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: recording_check DIR\n");
    return 2;
  }
  const std::string dir = argv[1];
  std::size_t incomplete = 0;
  try {
    for (const std::string& message : sl::drivers::incompleteRecordedSets(dir)) {
      std::printf("incomplete: %s\n", message.c_str());
      ++incomplete;
    }
    const auto reader = sl::drivers::RecordingReader::open(dir);
    for (std::size_t i = 0; i < reader->size(); ++i) {
      const sl::pipeline::ImageSet set = reader->load(i);
      uLong crc = crc32(0L, Z_NULL, 0);
      for (const auto& camera : set.cameras)
        for (const auto& frame : camera.frames) {
          const cv::Mat f = frame.isContinuous() ? frame : frame.clone();
          crc = crc32(crc, f.data, static_cast<uInt>(f.total() * f.elemSize()));
        }
      std::printf("set %s %08lx\n", reader->where(i).c_str(), static_cast<unsigned long>(crc));
    }
    std::printf("complete %zu incomplete %zu\n", reader->size(), incomplete);
    return 0;
  } catch (const std::exception& e) {
    std::printf("refused: %s\n", e.what());
    return 1;
  }
}
