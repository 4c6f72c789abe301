#include "sl/drivers/recording.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <yaml-cpp/yaml.h>

#include "replay/mcap_image_sets.h"

namespace sl::drivers {

namespace fs = std::filesystem;

namespace {

constexpr const char* kFormat = "sl-sensor-recording/1";

std::string setName(std::uint64_t index) {
  char name[32];
  std::snprintf(name, sizeof name, "set_%06llu", static_cast<unsigned long long>(index));
  return name;
}

std::string frameName(const std::string& camera, std::size_t i) {
  char name[32];
  std::snprintf(name, sizeof name, "_%02zu.png", i);
  return camera + name;
}

// Stamps are int64 ns; FileStorage stores int32 or double only, so they are
// written as decimal strings.
std::vector<std::string> toStrings(const std::vector<pipeline::TimestampNs>& stamps) {
  std::vector<std::string> out;
  for (auto s : stamps) out.push_back(std::to_string(s));
  return out;
}

// Reads a .yml file written by cv::FileStorage with yaml-cpp: OpenCV 4.6's
// own YAML parser loops for ever on some malformed files (fuzz_recording:
// a 24-byte "%YAML:1.0" file with a nested list item), so no file of a
// recording ever reaches it. Our files are small plain maps, lists and
// strings, which both read alike; OpenCV's "%YAML:1.0" first line is not
// YAML 1.2 and is skipped. Throws std::runtime_error naming the file.
YAML::Node loadOpenCvYaml(const std::string& path) {
  constexpr std::uintmax_t kMaxBytes = 1 << 20;  // a meta.yml is < 1 KB per camera
  std::error_code error;
  const std::uintmax_t bytes = fs::file_size(path, error);
  if (error) throw std::runtime_error(path + ": cannot read: " + error.message());
  if (bytes > kMaxBytes)
    throw std::runtime_error(path + ": " + std::to_string(bytes) + " bytes, more than a recording's " +
                             std::to_string(kMaxBytes));
  std::ifstream in(path, std::ios::binary);
  std::string text(static_cast<std::size_t>(bytes), '\0');
  if (!in.read(text.data(), static_cast<std::streamsize>(text.size())))
    throw std::runtime_error(path + ": cannot read");
  if (text.find('\0') != std::string::npos)
    throw std::runtime_error(path + ": contains a NUL byte, not a recording's YAML file");
  if (text.rfind("%YAML:", 0) == 0) {
    const std::size_t end = text.find('\n');
    text.erase(0, end == std::string::npos ? text.size() : end + 1);
  }
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": malformed: " + e.what());
  }
}

// A scalar of `node` (missing: ""); throws naming the file and key.
std::string scalarOf(const YAML::Node& node, const std::string& path, const char* key) {
  if (!node || node.IsNull()) return "";
  if (!node.IsScalar()) throw std::runtime_error(path + ": '" + key + "' must be a single value");
  return node.Scalar();
}

}  // namespace

void createRecording(const std::string& dir, const std::string& note) {
  std::error_code error;
  fs::create_directories(dir, error);
  if (error) throw std::runtime_error(dir + ": cannot create recording folder: " + error.message());
  const std::string path = (fs::path(dir) / "recording.yml").string();
  if (fs::exists(path)) return;
  cv::FileStorage out(path, cv::FileStorage::WRITE);
  if (!out.isOpened()) throw std::runtime_error(path + ": cannot write");
  out << "format" << kFormat;
  out << "created_ns" << std::to_string(pipeline::systemClockNs());
  out << "note" << note;
}

namespace {

// Writes `bytes` to `path` and checks every step, close included (a full
// disk shows at write or at close). Throws naming the file.
void writeFileChecked(const std::string& path, const void* bytes, std::size_t size) {
  std::FILE* out = std::fopen(path.c_str(), "wb");
  if (!out) throw std::runtime_error(path + ": cannot create: " + std::strerror(errno));
  const std::size_t written = size == 0 ? 0 : std::fwrite(bytes, 1, size, out);
  const int write_errno = errno;
  const bool flushed = std::fflush(out) == 0;
  const int flush_errno = errno;
  const bool closed = std::fclose(out) == 0;
  if (written != size)
    throw std::runtime_error(path + ": cannot write: " + std::strerror(write_errno));
  if (!flushed || !closed)
    throw std::runtime_error(path + ": cannot write: " + std::strerror(flushed ? errno : flush_errno));
}

// A set folder being written: "set_000001.partial" (renamed to the set's
// name once complete).
constexpr const char* kPartialSuffix = ".partial";

// The number of a set folder's name "set_NNNNNN" (exactly: digits only),
// or 0.
std::uint64_t setNumber(const std::string& name) {
  if (name.size() <= 4 || name.rfind("set_", 0) != 0) return 0;
  const std::string digits = name.substr(4);
  if (digits.size() > 18 || digits.find_first_not_of("0123456789") != std::string::npos) return 0;
  return std::stoull(digits);
}

}  // namespace

void writeRecordedSet(const std::string& dir, std::uint64_t index, const pipeline::ImageSet& set,
                      const std::string& pattern_yaml) {
  const fs::path final_folder = fs::path(dir) / setName(index);
  const fs::path folder = fs::path(dir) / (setName(index) + kPartialSuffix);
  std::error_code error;
  if (fs::exists(final_folder, error))
    throw std::runtime_error(final_folder.string() + ": exists already, not overwritten");
  fs::remove_all(folder, error);  // left by an interrupted write of this number
  fs::create_directories(folder, error);
  if (error) throw std::runtime_error(folder.string() + ": cannot create: " + error.message());
  try {
    for (const auto& camera : set.cameras) {
      for (std::size_t i = 0; i < camera.frames.size(); ++i) {
        const std::string path = (folder / frameName(camera.camera_id, i)).string();
        std::vector<unsigned char> png;
        if (!cv::imencode(".png", camera.frames[i], png, {cv::IMWRITE_PNG_COMPRESSION, 1}))
          throw std::runtime_error(path + ": cannot encode frame");
        writeFileChecked(path, png.data(), png.size());
      }
    }
    if (!pattern_yaml.empty()) {
      const std::string path = (folder / kRecordedPatternFile).string();
      writeFileChecked(path, pattern_yaml.data(), pattern_yaml.size());
    }
    const std::string meta = (folder / "meta.yml").string();
    cv::FileStorage out(meta, cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
    out << "sequence_id" << std::to_string(set.sequence_id);
    out << "pattern" << set.pattern_name;
    out << "trigger_stamp_ns" << std::to_string(set.trigger_stamp_ns);
    out << "cameras" << "[";
    for (const auto& camera : set.cameras) {
      out << "{" << "id" << camera.camera_id << "bit_depth" << camera.bit_depth
          << "frame_count" << static_cast<int>(camera.frames.size()) << "stamps_ns"
          << toStrings(camera.stamps_ns) << "}";
    }
    out << "]";
    const std::string text = out.releaseAndGetString();
    writeFileChecked(meta, text.data(), text.size());
    // Complete: the folder takes the set's name in one step.
    fs::rename(folder, final_folder, error);
    if (error)
      throw std::runtime_error(final_folder.string() + ": cannot rename " + folder.string() +
                               " to it: " + error.message());
  } catch (...) {
    fs::remove_all(folder, error);  // frees what the failed set took
    throw;
  }
}

std::uint64_t nextRecordedSetIndex(const std::string& dir) {
  std::uint64_t last = 0;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    std::string name = entry.path().filename().string();
    const std::size_t suffix = name.size() - std::min(name.size(), std::strlen(kPartialSuffix));
    if (name.compare(suffix, std::string::npos, kPartialSuffix) == 0) name.erase(suffix);
    last = std::max(last, setNumber(name));
  }
  return last + 1;
}

std::vector<std::string> incompleteRecordedSets(const std::string& dir) {
  std::vector<std::string> out;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("set_", 0) != 0 || !entry.is_directory(error)) continue;
    if (setNumber(name) == 0)
      out.push_back(entry.path().string() + ": not a complete set (" +
                    (name.size() > 8 && name.compare(name.size() - 8, 8, kPartialSuffix) == 0
                         ? "interrupted while it was written"
                         : "not a set folder name") +
                    "), skipped");
    else if (!fs::exists(entry.path() / "meta.yml"))
      out.push_back((entry.path() / "meta.yml").string() +
                    ": missing: an incomplete set (interrupted recording), skipped");
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> listRecordedSets(const std::string& dir) {
  const fs::path info = fs::path(dir) / "recording.yml";
  if (!fs::exists(info))
    throw std::runtime_error(dir + ": not a recording (no recording.yml)");
  std::string format;
  try {
    const YAML::Node in = loadOpenCvYaml(info.string());
    if (in.IsMap()) format = scalarOf(in["format"], info.string(), "format");
  } catch (const std::runtime_error&) {
  }
  if (format != kFormat)
    throw std::runtime_error(dir + ": not a recording (no readable recording.yml with format " +
                             kFormat + ")");
  std::vector<std::string> sets;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_directory() && setNumber(name) > 0 && fs::exists(entry.path() / "meta.yml"))
      sets.push_back(entry.path().string());
  }
  std::sort(sets.begin(), sets.end());
  return sets;
}

namespace {
pipeline::ImageSet readSet(const std::string& set_dir, const std::string& meta, bool load_images);
}  // namespace

pipeline::ImageSet readRecordedSet(const std::string& set_dir, bool load_images) {
  const std::string meta = (fs::path(set_dir) / "meta.yml").string();
  if (!fs::exists(meta)) throw std::runtime_error(meta + ": missing");
  // yaml-cpp throws YAML::Exception (and OpenCV's decoders cv::Exception):
  // all become the one error type naming the file.
  try {
    return readSet(set_dir, meta, load_images);
  } catch (const YAML::Exception& e) {  // a std::runtime_error: before the rethrow below
    throw std::runtime_error(meta + ": malformed: " + e.what());
  } catch (const std::runtime_error&) {
    throw;
  } catch (const cv::Exception& e) {
    throw std::runtime_error(meta + ": malformed: " + e.msg);
  } catch (const std::exception& e) {
    throw std::runtime_error(meta + ": malformed (" + e.what() + ")");
  }
}

namespace {

pipeline::ImageSet readSet(const std::string& set_dir, const std::string& meta, bool load_images) {
  const YAML::Node in = loadOpenCvYaml(meta);
  if (!in.IsMap()) throw std::runtime_error(meta + ": not a map of sequence_id, pattern, cameras");
  auto text = [&](const YAML::Node& node, const char* what) { return scalarOf(node, meta, what); };
  auto int64 = [&](const YAML::Node& node, const char* what) {
    const std::string value = text(node, what);
    std::size_t used = 0;
    try {
      const long long v = std::stoll(value, &used);
      if (used == value.size()) return static_cast<std::int64_t>(v);
    } catch (const std::exception&) {
    }
    throw std::runtime_error(meta + ": '" + what + "' is not an integer");
  };
  auto int32 = [&](const YAML::Node& node, const char* what) {
    const std::int64_t v = node && !node.IsNull() ? int64(node, what) : 0;
    if (v < -(1ll << 31) || v >= (1ll << 31)) throw std::runtime_error(meta + ": '" + what + "' is out of range");
    return static_cast<int>(v);
  };
  pipeline::ImageSet set;
  set.sequence_id = static_cast<std::uint64_t>(int64(in["sequence_id"], "sequence_id"));
  set.pattern_name = text(in["pattern"], "pattern");
  set.trigger_stamp_ns = int64(in["trigger_stamp_ns"], "trigger_stamp_ns");
  const YAML::Node cameras = in["cameras"];
  if (!cameras.IsSequence() || cameras.size() == 0)
    throw std::runtime_error(meta + ": 'cameras' must be a non-empty list");
  for (const YAML::Node& node : cameras) {
    if (!node.IsMap()) throw std::runtime_error(meta + ": a 'cameras' entry must be a map");
    pipeline::CameraImages camera;
    camera.camera_id = text(node["id"], "id");
    camera.bit_depth = int32(node["bit_depth"], "bit_depth");
    const int frame_count = int32(node["frame_count"], "frame_count");
    const YAML::Node stamps = node["stamps_ns"];
    if (camera.camera_id.empty() || frame_count <= 0 || !stamps.IsSequence() ||
        static_cast<int>(stamps.size()) != frame_count)
      throw std::runtime_error(meta + ": camera entry needs id, frame_count and as many stamps_ns");
    // The id names the frame files: a plain name, so that no frame is read
    // from outside the set folder ("../x"), and bounded counts.
    if (camera.camera_id.size() > 64 ||
        camera.camera_id.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                                           "0123456789_-") != std::string::npos)
      throw std::runtime_error(meta + ": camera id '" + camera.camera_id.substr(0, 64) +
                               "' is not a plain name (letters, digits, _ and -, at most 64)");
    if (frame_count > 1024)
      throw std::runtime_error(meta + ": frame_count " + std::to_string(frame_count) +
                               " is more than 1024");
    if (camera.bit_depth < 1 || camera.bit_depth > 16)
      throw std::runtime_error(meta + ": bit_depth " + std::to_string(camera.bit_depth) +
                               " is not 1..16");
    for (const YAML::Node& s : stamps) camera.stamps_ns.push_back(int64(s, "stamps_ns"));
    for (int i = 0; load_images && i < frame_count; ++i) {
      const std::string path = (fs::path(set_dir) / frameName(camera.camera_id, i)).string();
      cv::Mat image;
      try {
        image = cv::imread(path, cv::IMREAD_UNCHANGED);
      } catch (const cv::Exception& e) {
        throw std::runtime_error(path + ": unreadable frame: " + e.msg);
      }
      if (image.empty()) throw std::runtime_error(path + ": missing or unreadable frame (truncated PNG?)");
      if (image.channels() != 1) throw std::runtime_error(path + ": not a single-channel image");
      // The depth the metadata promises: 8-bit frames up to 8 bits, 16-bit above.
      const int expected_depth = camera.bit_depth > 8 ? CV_16U : CV_8U;
      if (image.depth() != expected_depth)
        throw std::runtime_error(path + ": " + (image.depth() == CV_16U ? "16" : "8 or other") +
                                 "-bit frame, but meta.yml says bit_depth " +
                                 std::to_string(camera.bit_depth));
      if (!camera.frames.empty() && image.size() != camera.frames.front().size())
        throw std::runtime_error(path + ": " + std::to_string(image.cols) + "x" +
                                 std::to_string(image.rows) + ", other frames of the camera are " +
                                 std::to_string(camera.frames.front().cols) + "x" +
                                 std::to_string(camera.frames.front().rows));
      camera.frames.push_back(image);
    }
    set.cameras.push_back(std::move(camera));
  }
  return set;
}

}  // namespace

namespace {

class FolderRecording : public RecordingReader {
 public:
  explicit FolderRecording(const std::string& dir) {
    for (const std::string& folder : listRecordedSets(dir)) {
      folders_.push_back(folder);
      infos_.push_back(readRecordedSet(folder, /*load_images=*/false));
    }
    if (infos_.empty()) {
      const std::vector<std::string> incomplete = incompleteRecordedSets(dir);
      throw std::runtime_error(dir + ": the recording holds no complete image sets" +
                               (incomplete.empty() ? std::string() : " (" + incomplete.front() + ")"));
    }
  }
  std::size_t size() const override { return infos_.size(); }
  const pipeline::ImageSet& info(std::size_t i) const override { return infos_.at(i); }
  pipeline::ImageSet load(std::size_t i) const override { return readRecordedSet(folders_.at(i)); }
  std::string where(std::size_t i) const override { return folders_.at(i); }
  std::string whereFrame(std::size_t i, const std::string& camera, std::size_t frame) const override {
    return (fs::path(folders_.at(i)) / frameName(camera, frame)).string();
  }

 private:
  std::vector<std::string> folders_;
  std::vector<pipeline::ImageSet> infos_;
};

class McapRecording : public RecordingReader {
 public:
  explicit McapRecording(const std::string& path) : sets_(path) {}
  std::size_t size() const override { return sets_.size(); }
  const pipeline::ImageSet& info(std::size_t i) const override { return sets_.info(i); }
  pipeline::ImageSet load(std::size_t i) const override { return sets_.load(i); }
  std::string where(std::size_t i) const override { return sets_.where(i); }
  std::string whereFrame(std::size_t i, const std::string& camera, std::size_t frame) const override {
    return sets_.where(i) + ": camera '" + camera + "' image " + std::to_string(frame);
  }

 private:
  McapImageSets sets_;
};

}  // namespace

std::unique_ptr<RecordingReader> RecordingReader::open(const std::string& path) {
  std::error_code error;
  const fs::file_status status = fs::status(path, error);
  if (error || !fs::exists(status))
    throw std::runtime_error(path + ": not a recording (no such folder or MCAP file)");
  if (fs::is_directory(status)) return std::make_unique<FolderRecording>(path);
  return std::make_unique<McapRecording>(path);
}

}  // namespace sl::drivers
