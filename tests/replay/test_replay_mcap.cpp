// Recordings as MCAP files (sl_view record of the daemon's image sets): the
// replay reads them into the same ImageSets a recording folder gives, and a
// file without image sets, truncated or corrupt is refused naming the file.
// The files here are written with the project's MCAP writer
// (tools/common/mcap_writer.h, itself checked by @mcap/core in view_wire) and
// an ImageSet CDR encoder written from ros2/sl_msgs/msg/ImageSet.msg; the
// daemon's own bytes are replayed end to end in tests/view/mcap_replay_test.sh.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <opencv2/core.hpp>

#include "common/mcap_writer.h"
#include "common/ros2_schemas.h"
#include "replay/mcap_image_sets.h"
#include "sl/drivers/recording.h"
#include "sl/drivers/replay.h"
#include "support/time_scale.h"

using namespace std::chrono_literals;
using sl::pipeline::ImageSet;

namespace {

std::string tempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("sl_test_" + name + "_" + std::to_string(::getpid())))
      .string();
}

ImageSet makeSet(std::uint64_t id, const std::string& pattern, int frames, int depth) {
  ImageSet set;
  set.sequence_id = id;
  set.pattern_name = pattern;
  set.trigger_stamp_ns = 1'700'000'000'000'000'000 + std::int64_t(id) * 200'000'000;
  for (const char* camera : {"top", "left"}) {
    sl::pipeline::CameraImages images;
    images.camera_id = camera;
    images.bit_depth = depth;
    for (int i = 0; i < frames; ++i) {
      cv::Mat image(48, 64, depth > 8 ? CV_16UC1 : CV_8UC1);
      cv::randu(image, 0, depth > 8 ? 4096 : 256);
      images.frames.push_back(image);
      images.stamps_ns.push_back(set.trigger_stamp_ns + i * 33'333'333 + 1000 * i);
    }
    set.cameras.push_back(images);
  }
  return set;
}

// XCDR1 little endian, as Cyclone writes sl_msgs/msg/ImageSet.
class CdrOut {
 public:
  CdrOut() : bytes_("\x00\x01\x00\x00", 4) {}
  template <class T>
  void put(T v) {
    while ((bytes_.size() - 4) % sizeof(T) != 0) bytes_.push_back('\0');
    bytes_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void string(const std::string& s) {
    put<std::uint32_t>(static_cast<std::uint32_t>(s.size() + 1));
    bytes_.append(s);
    bytes_.push_back('\0');
  }
  void stamp(std::int64_t ns) {
    put<std::int32_t>(static_cast<std::int32_t>(ns / 1'000'000'000));
    put<std::uint32_t>(static_cast<std::uint32_t>(ns % 1'000'000'000));
  }
  void raw(const void* data, std::size_t n) { bytes_.append(static_cast<const char*>(data), n); }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

std::string encode(const ImageSet& set) {
  CdrOut out;
  out.stamp(set.trigger_stamp_ns);
  out.string("");
  out.string(set.pattern_name);
  out.put<std::uint64_t>(set.sequence_id);
  out.put<std::uint32_t>(static_cast<std::uint32_t>(set.cameras.size()));
  out.put<std::uint32_t>(static_cast<std::uint32_t>(set.cameras.size()));
  for (const auto& c : set.cameras) out.string(c.camera_id);
  out.put<std::uint32_t>(static_cast<std::uint32_t>(set.cameras.size()));
  for (const auto& c : set.cameras) out.put<std::uint8_t>(static_cast<std::uint8_t>(c.bit_depth));
  std::uint32_t images = 0;
  for (const auto& c : set.cameras) images += static_cast<std::uint32_t>(c.frames.size());
  out.put<std::uint32_t>(images);
  for (const auto& c : set.cameras) {
    for (std::size_t i = 0; i < c.frames.size(); ++i) {
      const cv::Mat& m = c.frames[i];
      out.stamp(c.stamps_ns[i]);
      out.string(c.camera_id + "_optical_frame");
      out.put<std::uint32_t>(m.rows);
      out.put<std::uint32_t>(m.cols);
      out.string(m.elemSize() == 1 ? "mono8" : "mono16");
      out.put<std::uint8_t>(0);
      out.put<std::uint32_t>(static_cast<std::uint32_t>(m.cols * m.elemSize()));
      out.put<std::uint32_t>(static_cast<std::uint32_t>(m.total() * m.elemSize()));
      out.raw(m.data, m.total() * m.elemSize());
    }
  }
  return out.bytes();
}

// An MCAP file as `sl_view record --topics /t/points,/t/image_sets` writes it
// (a points channel with one message between the sets).
void writeMcap(const std::string& path, const std::vector<ImageSet>& sets,
               const std::string& compression, bool with_sets = true) {
  sl::tools::McapWriterOptions options;
  options.compression = compression;
  options.chunk_size = 64 << 10;  // several chunks
  sl::tools::McapWriter writer(path, options);
  const auto& points_schema = sl::tools::ros2Schema("sensor_msgs/msg/PointCloud2");
  const auto points = writer.addChannel(
      writer.addSchema(points_schema.name, "ros2msg", points_schema.definition), "/t/points", "cdr");
  const auto& sets_schema = sl::tools::ros2Schema("sl_msgs/msg/ImageSet");
  const auto channel = writer.addChannel(
      writer.addSchema(sets_schema.name, "ros2msg", sets_schema.definition), "/t/image_sets", "cdr");
  std::uint32_t n = 0;
  for (const ImageSet& set : sets) {
    const auto t = static_cast<std::uint64_t>(set.trigger_stamp_ns);
    if (with_sets) writer.write(channel, ++n, t, t, encode(set));
    writer.write(points, n, t + 1, t + 1, std::string("\x00\x01\x00\x00not a cloud", 15));
  }
  writer.close();
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

void writeFile(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

void requireEqual(const ImageSet& a, const ImageSet& b, bool frames) {
  CHECK(a.sequence_id == b.sequence_id);
  CHECK(a.pattern_name == b.pattern_name);
  CHECK(a.trigger_stamp_ns == b.trigger_stamp_ns);
  REQUIRE(a.cameras.size() == b.cameras.size());
  for (std::size_t c = 0; c < a.cameras.size(); ++c) {
    CHECK(a.cameras[c].camera_id == b.cameras[c].camera_id);
    CHECK(a.cameras[c].bit_depth == b.cameras[c].bit_depth);
    CHECK(a.cameras[c].stamps_ns == b.cameras[c].stamps_ns);
    if (!frames) continue;
    REQUIRE(a.cameras[c].frames.size() == b.cameras[c].frames.size());
    for (std::size_t i = 0; i < a.cameras[c].frames.size(); ++i)
      CHECK(identical(a.cameras[c].frames[i], b.cameras[c].frames[i]));
  }
}

}  // namespace

TEST_CASE("an MCAP file of image sets reads back as the recording folder of the same sets") {
  const std::string compression = GENERATE(std::string("zstd"), std::string("lz4"), std::string(""));
  const int depth = GENERATE(8, 12);
  INFO("compression '" << compression << "', bit depth " << depth);
  std::vector<ImageSet> sets;
  for (std::uint64_t k = 0; k < 3; ++k) sets.push_back(makeSet(k + 5, k == 1 ? "other" : "p", 6, depth));
  const std::string path = tempPath("sets") + ".mcap", dir = tempPath("sets_dir");
  std::filesystem::remove_all(dir);
  writeMcap(path, sets, compression);
  sl::drivers::createRecording(dir, "");
  for (std::size_t k = 0; k < sets.size(); ++k) sl::drivers::writeRecordedSet(dir, k + 1, sets[k]);

  const auto mcap = sl::drivers::RecordingReader::open(path);
  const auto folder = sl::drivers::RecordingReader::open(dir);
  REQUIRE(mcap->size() == 3);
  REQUIRE(folder->size() == 3);
  for (std::size_t k = 0; k < 3; ++k) {
    requireEqual(mcap->info(k), folder->info(k), false);
    CHECK(mcap->info(k).cameras[0].frames.empty());
    requireEqual(mcap->load(k), folder->load(k), true);
    requireEqual(mcap->load(k), sets[k], true);
  }
  CHECK(mcap->where(1) == path + ": image set 2 (message 3)");
  std::filesystem::remove(path);
  std::filesystem::remove_all(dir);
}

TEST_CASE("the replay sensor plays an MCAP file's image sets") {
  std::vector<ImageSet> sets;
  for (std::uint64_t k = 0; k < 3; ++k) sets.push_back(makeSet(k, "p", 6, 8));
  const std::string path = tempPath("replay") + ".mcap";
  writeMcap(path, sets, "zstd");
  const auto replay = sl::drivers::ReplaySensor::open({path, /*loop=*/false, 0});
  CHECK(replay->setCount() == 3);
  auto cameras = replay->cameras();
  REQUIRE(cameras.size() == 2);
  CHECK(cameras[1]->id() == "left");
  CHECK(cameras[1]->width() == 64);
  auto projector = replay->projector();
  auto trigger = replay->triggerSource();
  projector->select("p");
  projector->start(2);
  std::vector<sl::drivers::TriggerEvent> triggers;
  for (int k = 0; k < 2; ++k) {
    auto t = trigger->next(sl::test::scaledBound(2s));
    REQUIRE(t);
    triggers.push_back(*t);
  }
  for (std::size_t c = 0; c < 2; ++c)
    for (int k = 0; k < 2; ++k)
      for (int i = 0; i < 6; ++i) {
        auto frame = cameras[c]->grab(sl::test::scaledBound(2s));
        REQUIRE(frame);
        CHECK(identical(frame->image, sets[k].cameras[c].frames[i]));
        CHECK(frame->stamp_ns - triggers[k].stamp_ns ==
              sets[k].cameras[c].stamps_ns[i] - sets[k].trigger_stamp_ns);
      }
  projector->stop();
  std::filesystem::remove(path);
}

TEST_CASE("an MCAP file without image sets is refused, naming the file and its topics") {
  const std::string path = tempPath("no_sets") + ".mcap";
  writeMcap(path, {makeSet(1, "p", 3, 8)}, "zstd", /*with_sets=*/false);
  CHECK_THROWS_WITH(sl::drivers::RecordingReader::open(path),
                    Catch::Contains(path + ": holds no image sets") && Catch::Contains("/t/points") &&
                        Catch::Contains("dds.publish_image_sets: true"));
  CHECK_THROWS_WITH(sl::drivers::ReplaySensor::open({path, false, 0}),
                    Catch::Contains(path + ": holds no image sets"));
  std::filesystem::remove(path);
}

TEST_CASE("a truncated or corrupt MCAP file is refused, naming the file and record") {
  const std::string compression = GENERATE(std::string("zstd"), std::string("lz4"), std::string(""));
  INFO("compression '" << compression << "'");
  const std::string good = tempPath("good") + ".mcap", bad = tempPath("bad") + ".mcap";
  const std::vector<ImageSet> sets = {makeSet(1, "p", 6, 8), makeSet(2, "p", 6, 8)};
  writeMcap(good, sets, compression);
  const std::string bytes = readFile(good);
  REQUIRE(bytes.size() > 50'000);  // two sets of 12 random 64x48 frames

  // Cut anywhere: no closing magic.
  for (const std::size_t keep : {std::size_t{0}, std::size_t{5}, std::size_t{8}, std::size_t{30},
                                 bytes.size() / 3, bytes.size() / 2, bytes.size() - 9, bytes.size() - 1}) {
    INFO("kept " << keep << " of " << bytes.size() << " bytes");
    writeFile(bad, bytes.substr(0, keep));
    CHECK_THROWS_WITH(sl::drivers::RecordingReader::open(bad), Catch::StartsWith(bad + ": "));
  }
  writeFile(bad, bytes.substr(0, bytes.size() / 2));
  CHECK_THROWS_WITH(sl::drivers::RecordingReader::open(bad), Catch::Contains("truncated"));
  // Cut in the middle but closed with the magic again (a copy that lost a
  // block): the record running past the end is named.
  writeFile(bad, bytes.substr(0, bytes.size() / 2) + bytes.substr(bytes.size() - 8));
  CHECK_THROWS_WITH(sl::drivers::RecordingReader::open(bad),
                    Catch::StartsWith(bad + ": record ") && Catch::Contains("at byte"));

  // A flipped byte in each stretch of the data section: an error naming the
  // file (chunk CRCs catch flipped pixels), or, where the byte is one the
  // replay does not use (times, indexes), the original sets; never a wrong set.
  const std::size_t data_end = bytes.size() / 10 * 9;
  for (std::size_t at = 8; at < data_end; at += bytes.size() / 37) {
    INFO("byte " << at << " flipped");
    std::string corrupt = bytes;
    corrupt[at] = static_cast<char>(corrupt[at] ^ 0x5A);
    writeFile(bad, corrupt);
    try {
      const auto recording = sl::drivers::RecordingReader::open(bad);
      REQUIRE(recording->size() == sets.size());
      for (std::size_t k = 0; k < recording->size(); ++k) {
        try {
          requireEqual(recording->load(k), sets[k], true);
        } catch (const std::runtime_error& e) {
          CHECK_THAT(e.what(), Catch::StartsWith(bad + ": "));
        }
      }
    } catch (const std::runtime_error& e) {
      CHECK_THAT(e.what(), Catch::StartsWith(bad + ": "));
    }
  }
  std::filesystem::remove(good);
  std::filesystem::remove(bad);
}

// A chunk may declare up to 2 GB of records, but no more than its compressed
// bytes can expand to: a small file declaring a huge chunk is refused before
// the reader allocates (fuzz_recording: a 407-byte file made it allocate and
// clear 1.9 GB, over 10 s under ASan).
TEST_CASE("a compressed chunk declaring more than its bytes can hold is refused before allocating") {
  const std::string compression = GENERATE(std::string("zstd"), std::string("lz4"));
  INFO("compression '" << compression << "'");
  const std::string good = tempPath("ratio_good") + ".mcap", bad = tempPath("ratio_bad") + ".mcap";
  writeMcap(good, {makeSet(1, "p", 2, 8)}, compression);
  std::string bytes = readFile(good);
  // Records after the 8-byte magic: opcode, u64 length, body. A chunk's body
  // begins with start and end times, then the uncompressed size.
  std::size_t at = 8, chunks = 0;
  while (at + 9 <= bytes.size() - 8) {
    std::uint64_t length = 0;
    std::memcpy(&length, &bytes[at + 1], 8);
    if (bytes[at] == 0x06) {
      const std::uint64_t declared = 1'900'000'000;
      std::memcpy(&bytes[at + 9 + 16], &declared, 8);
      ++chunks;
    }
    at += 9 + length;
  }
  REQUIRE(chunks >= 1);
  writeFile(bad, bytes);
  CHECK_THROWS_WITH(sl::drivers::RecordingReader::open(bad),
                    Catch::StartsWith(bad + ": ") && Catch::Contains("uncompressed size 1900000000 cannot come from") &&
                        Catch::Contains("bytes of " + compression));
  std::filesystem::remove(good);
  std::filesystem::remove(bad);
}

TEST_CASE("an image set message that contradicts itself is refused, naming the message") {
  const ImageSet set = makeSet(1, "p", 2, 8);
  const std::string good = encode(set);
  CHECK_NOTHROW(sl::drivers::decodeImageSetCdr(good, "m", true));
  auto patched = [&](std::size_t at, std::uint32_t value) {
    std::string b = good;
    std::memcpy(&b[at], &value, 4);
    return b;
  };
  // Offsets (after the 4-byte header): stamp 0..7, frame_id "" 8..12,
  // pattern "p" 16..21, sequence_id 24, camera_count 32.
  CHECK_THROWS_WITH(sl::drivers::decodeImageSetCdr(patched(4 + 32, 0), "msg 3", false),
                    Catch::StartsWith("msg 3: camera_count 0"));
  CHECK_THROWS_WITH(sl::drivers::decodeImageSetCdr(patched(4 + 36, 1 << 30), "msg 3", false),
                    Catch::Contains("do not fit"));
  CHECK_THROWS_WITH(sl::drivers::decodeImageSetCdr(good.substr(0, good.size() - 1), "msg 3", false),
                    Catch::StartsWith("msg 3: image data"));
  std::string big_endian = good;
  big_endian[1] = 0;
  CHECK_THROWS_WITH(sl::drivers::decodeImageSetCdr(big_endian, "msg 3", false),
                    Catch::Contains("not plain little-endian CDR"));
}

// fuzz_recording's MCAP seeds (after their mode byte) were written by a
// Python script and the zstd / lz4 command-line tools, not by the project's
// writer: the reader takes their chunks too, and the truncated one is named.
TEST_CASE("MCAP files from another writer (the fuzz seeds) read back") {
  const std::string corpus = std::string(SL_SOURCE_DIR) + "/fuzz/corpus/recording/";
  const std::string path = tempPath("seed") + ".mcap";
  for (const std::string name : {"mcap_none", "mcap_zstd", "mcap_lz4", "mcap_truncated"}) {
    INFO(name);
    const std::string bytes = readFile(corpus + name);
    REQUIRE(bytes.size() > 1);
    REQUIRE(bytes[0] == '2');  // the fuzzer's MCAP mode
    writeFile(path, bytes.substr(1));
    if (name == "mcap_truncated") {
      CHECK_THROWS_WITH(sl::drivers::RecordingReader::open(path),
                        Catch::StartsWith(path + ": truncated or not closed"));
      continue;
    }
    const auto recording = sl::drivers::RecordingReader::open(path);
    REQUIRE(recording->size() == 1);
    const ImageSet set = recording->load(0);
    CHECK(set.pattern_name == "p");
    CHECK(set.sequence_id == 7);
    CHECK(set.trigger_stamp_ns == 1'700'000'000'000'000'005);
    REQUIRE(set.cameras.size() == 1);
    CHECK(set.cameras[0].camera_id == "cam");
    REQUIRE(set.cameras[0].frames.size() == 3);
    CHECK(set.cameras[0].stamps_ns[2] == 1'700'000'000'000'002'005);
    CHECK(set.cameras[0].frames[2].at<std::uint8_t>(1, 3) == 2 + 7);  // bytes i..i+7, 4x2
  }
  std::filesystem::remove(path);
}
