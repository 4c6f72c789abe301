#include "replay/mcap_image_sets.h"

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>

#include <lz4frame.h>
#include <opencv2/core.hpp>
#include <zlib.h>
#include <zstd.h>

namespace sl::drivers {

namespace {

constexpr char kMagic[8] = {'\x89', 'M', 'C', 'A', 'P', '0', '\r', '\n'};
enum Op : std::uint8_t {
  kHeader = 0x01, kFooter = 0x02, kSchema = 0x03, kChannel = 0x04, kMessage = 0x05,
  kChunk = 0x06, kDataEnd = 0x0F,
};
constexpr std::uint64_t kRecordHeader = 1 + 8;       // opcode, length
constexpr std::uint64_t kFooterBody = 8 + 8 + 4;     // summary start, offset start, crc
constexpr std::uint64_t kMaxChunkBytes = 1ull << 31; // uncompressed records of one chunk
// The most a compressed byte can expand to, with a margin, so that a chunk's
// declared size is checked against its compressed bytes before allocating
// for it: an LZ4 match length grows by 255 per extra byte; a zstd RLE block
// of 4 bytes gives at most 128 KiB.
constexpr std::uint64_t kMaxLz4Ratio = 256, kMaxZstdRatio = 32768, kRatioSlack = 1 << 16;
constexpr std::uint64_t kMaxSmallRecord = 16 << 20;  // schema, channel (text)
constexpr std::uint64_t kMessagePrefix = 2 + 4 + 8 + 8;  // channel, sequence, log, publish time

const char* opName(std::uint8_t op) {
  switch (op) {
    case kHeader: return "header";
    case kFooter: return "footer";
    case kSchema: return "schema";
    case kChannel: return "channel";
    case kMessage: return "message";
    case kChunk: return "chunk";
    case kDataEnd: return "data end";
    default: return "record";
  }
}

// CRC-32 (IEEE 802.3), as MCAP uses: zlib's.
std::uint32_t crc32(std::string_view bytes) {
  return static_cast<std::uint32_t>(::crc32_z(0L, reinterpret_cast<const Bytef*>(bytes.data()), bytes.size()));
}

// Little-endian fields of an MCAP record body, bounds-checked; errors name
// `what`. Holds a view: the bytes must outlive it (fuzz_recording found a
// record header read into a temporary).
class Fields {
 public:
  Fields(std::string_view data, std::string what) : data_(data), what_(std::move(what)) {}
  template <class T>
  T le() {
    const std::string_view b = take(sizeof(T));
    T v{};
    std::memcpy(&v, b.data(), sizeof(T));  // little-endian host (x86-64, arm64)
    return v;
  }
  std::string_view take(std::uint64_t n) {
    if (n > data_.size() - pos_)
      fail("needs " + std::to_string(n) + " bytes at offset " + std::to_string(pos_) + ", " +
           std::to_string(data_.size() - pos_) + " left (truncated or corrupt)");
    const std::string_view b = data_.substr(pos_, n);
    pos_ += n;
    return b;
  }
  std::string string() { return std::string(take(le<std::uint32_t>())); }
  std::string_view rest() { return take(data_.size() - pos_); }
  std::size_t offset() const { return pos_; }
  [[noreturn]] void fail(const std::string& message) const {
    throw std::runtime_error(what_ + ": " + message);
  }

 private:
  std::string_view data_;
  std::size_t pos_ = 0;
  std::string what_;
};

// XCDR1 little-endian reader: primitives aligned to their size, counted
// relative to the byte after the encapsulation header.
class Cdr {
 public:
  Cdr(std::string_view data, const std::string& what) : data_(data), what_(what) {}
  template <class T>
  T get() {
    align(sizeof(T));
    T v{};
    std::memcpy(&v, take(sizeof(T)).data(), sizeof(T));
    return v;
  }
  std::string string(const char* field) {
    const auto n = get<std::uint32_t>();
    if (n == 0) fail(std::string(field) + ": a string of length 0 (no terminating NUL)");
    const std::string_view b = take(n, field);
    if (b.back() != '\0') fail(std::string(field) + ": string without its terminating NUL");
    return std::string(b.substr(0, n - 1));
  }
  // A sequence length whose elements take at least `min_bytes` each.
  std::uint32_t count(const char* field, std::size_t min_bytes) {
    const auto n = get<std::uint32_t>();
    if (std::uint64_t(n) * min_bytes > data_.size() - pos_)
      fail(std::string(field) + ": " + std::to_string(n) + " elements do not fit in the " +
           std::to_string(data_.size() - pos_) + " bytes left");
    return n;
  }
  std::string_view take(std::size_t n, const char* field = "field") {
    if (n > data_.size() - pos_)
      fail(std::string(field) + ": needs " + std::to_string(n) + " bytes at offset " +
           std::to_string(pos_) + ", " + std::to_string(data_.size() - pos_) + " left");
    const std::string_view b = data_.substr(pos_, n);
    pos_ += n;
    return b;
  }
  [[noreturn]] void fail(const std::string& message) const {
    throw std::runtime_error(what_ + ": " + message);
  }

 private:
  void align(std::size_t n) {
    const std::size_t aligned = (pos_ + n - 1) / n * n;
    if (aligned > data_.size()) fail("ends inside the alignment padding");
    pos_ = aligned;
  }
  std::string_view data_;
  std::size_t pos_ = 0;
  const std::string& what_;
};

pipeline::TimestampNs stampNs(Cdr& cdr) {
  const auto sec = cdr.get<std::int32_t>();
  const auto nanosec = cdr.get<std::uint32_t>();
  if (nanosec >= 1'000'000'000u) cdr.fail("a stamp's nanosec " + std::to_string(nanosec) + " is 1 s or more");
  return std::int64_t(sec) * 1'000'000'000 + nanosec;
}

// The file, read at offsets; errors name it.
class File {
 public:
  explicit File(const std::string& path) : path_(path), in_(path, std::ios::binary) {
    std::error_code error;
    size_ = std::filesystem::file_size(path, error);
    if (error || !in_) throw std::runtime_error(path + ": cannot read: " + error.message());
  }
  std::uint64_t size() const { return size_; }
  std::string read(std::uint64_t offset, std::uint64_t n) {
    if (offset > size_ || n > size_ - offset)
      throw std::runtime_error(path_ + ": " + std::to_string(n) + " bytes at byte " +
                               std::to_string(offset) + " run past the end of the file (" +
                               std::to_string(size_) + " bytes)");
    std::string bytes(static_cast<std::size_t>(n), '\0');
    in_.seekg(static_cast<std::streamoff>(offset));
    if (!in_.read(bytes.data(), static_cast<std::streamsize>(n)))
      throw std::runtime_error(path_ + ": read error at byte " + std::to_string(offset));
    return bytes;
  }

 private:
  std::string path_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
};

// The uncompressed records of a chunk record's body; `what` names the chunk.
std::string chunkRecords(std::string_view body, const std::string& what) {
  Fields f(body, what);
  f.le<std::uint64_t>();  // message start time
  f.le<std::uint64_t>();  // message end time
  const auto uncompressed_size = f.le<std::uint64_t>();
  const auto uncompressed_crc = f.le<std::uint32_t>();
  const std::string compression = f.string();
  const std::string_view records = f.take(f.le<std::uint64_t>());
  if (uncompressed_size > kMaxChunkBytes)
    f.fail("uncompressed size " + std::to_string(uncompressed_size) + " is more than " +
           std::to_string(kMaxChunkBytes));
  const std::uint64_t ratio = compression == "lz4" ? kMaxLz4Ratio : compression == "zstd" ? kMaxZstdRatio : 0;
  if (ratio > 0 && uncompressed_size > records.size() * ratio + kRatioSlack)
    f.fail("uncompressed size " + std::to_string(uncompressed_size) + " cannot come from " +
           std::to_string(records.size()) + " bytes of " + compression);
  std::string out;
  if (compression.empty()) {
    if (records.size() != uncompressed_size)
      f.fail("uncompressed chunk of " + std::to_string(records.size()) + " bytes, its header says " +
             std::to_string(uncompressed_size));
    out.assign(records);
  } else if (compression == "zstd") {
    // Refuse a frame that declares another size before allocating for it.
    const unsigned long long declared = ZSTD_getFrameContentSize(records.data(), records.size());
    if (declared == ZSTD_CONTENTSIZE_ERROR) f.fail("zstd: not a zstd frame");
    if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != uncompressed_size)
      f.fail("zstd frame of " + std::to_string(declared) + " bytes, the chunk says " +
             std::to_string(uncompressed_size));
    out.resize(static_cast<std::size_t>(uncompressed_size));
    const std::size_t n = ZSTD_decompress(out.data(), out.size(), records.data(), records.size());
    if (ZSTD_isError(n)) f.fail(std::string("zstd: ") + ZSTD_getErrorName(n));
    if (n != uncompressed_size)
      f.fail("zstd gave " + std::to_string(n) + " bytes, the chunk says " + std::to_string(uncompressed_size));
  } else if (compression == "lz4") {
    LZ4F_dctx* context = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&context, LZ4F_VERSION)))
      f.fail("lz4: cannot create a decompression context");
    out.resize(static_cast<std::size_t>(uncompressed_size));
    std::size_t in_pos = 0, out_pos = 0, hint = 1;
    while (hint != 0 && in_pos < records.size()) {
      std::size_t in_n = records.size() - in_pos, out_n = out.size() - out_pos;
      hint = LZ4F_decompress(context, out.data() + out_pos, &out_n, records.data() + in_pos, &in_n,
                             nullptr);
      if (LZ4F_isError(hint)) {
        const std::string error = LZ4F_getErrorName(hint);
        LZ4F_freeDecompressionContext(context);
        f.fail("lz4: " + error);
      }
      in_pos += in_n;
      out_pos += out_n;
      if (in_n == 0 && out_n == 0) break;  // output full, frame not done
    }
    LZ4F_freeDecompressionContext(context);
    if (hint != 0 || out_pos != uncompressed_size)
      f.fail("lz4 frame incomplete or of another size (" + std::to_string(out_pos) +
             " bytes, the chunk says " + std::to_string(uncompressed_size) + ")");
  } else {
    f.fail("compression '" + compression.substr(0, 32) + "' is not zstd, lz4 or none");
  }
  if (uncompressed_crc != 0 && crc32(out) != uncompressed_crc)
    f.fail("CRC mismatch: the chunk's records are corrupt");
  return out;
}

// A record inside `bytes` at `offset`: opcode and body.
struct Record {
  std::uint8_t op;
  std::string_view body;
};
Record recordAt(std::string_view bytes, std::uint64_t offset, const std::string& what) {
  Fields f(bytes.substr(offset), what);
  const auto op = f.le<std::uint8_t>();
  const auto length = f.le<std::uint64_t>();
  return {op, f.take(length)};
}

}  // namespace

pipeline::ImageSet decodeImageSetCdr(std::string_view cdr, const std::string& what,
                                     bool load_images) {
  if (cdr.size() < 4) throw std::runtime_error(what + ": " + std::to_string(cdr.size()) + " bytes, no CDR header");
  if (cdr[0] != 0 || cdr[1] != 1)
    throw std::runtime_error(what + ": CDR encapsulation " + std::to_string(int(std::uint8_t(cdr[0]))) +
                             "," + std::to_string(int(std::uint8_t(cdr[1]))) +
                             " is not plain little-endian CDR (0,1) as the daemon writes");
  Cdr in(cdr.substr(4), what);
  pipeline::ImageSet set;
  set.trigger_stamp_ns = stampNs(in);
  in.string("header.frame_id");
  set.pattern_name = in.string("pattern");
  set.sequence_id = in.get<std::uint64_t>();
  const auto camera_count = in.get<std::uint32_t>();
  if (camera_count < 1 || camera_count > 8)
    in.fail("camera_count " + std::to_string(camera_count) + " is not 1..8");
  const auto ids = in.count("camera_ids", 5);
  if (ids != camera_count)
    in.fail(std::to_string(ids) + " camera_ids for camera_count " + std::to_string(camera_count));
  set.cameras.resize(camera_count);
  for (auto& camera : set.cameras) {
    camera.camera_id = in.string("camera_ids");
    if (camera.camera_id.empty() || camera.camera_id.size() > 64)
      in.fail("camera id '" + camera.camera_id.substr(0, 64) + "' is empty or longer than 64");
  }
  if (in.count("bit_depths", 1) != camera_count)
    in.fail("bit_depths and camera_count " + std::to_string(camera_count) + " differ in length");
  for (auto& camera : set.cameras) {
    camera.bit_depth = in.get<std::uint8_t>();
    if (camera.bit_depth < 1 || camera.bit_depth > 16)
      in.fail("camera '" + camera.camera_id + "': bit_depth " + std::to_string(camera.bit_depth) +
              " is not 1..16");
  }
  // An image: header (stamp 8, frame_id >= 5), height, width, encoding >= 5,
  // is_bigendian, step, data length.
  const auto images = in.count("images", 8 + 5 + 4 + 4 + 5 + 1 + 4 + 4);
  if (images == 0 || images % camera_count != 0 || images / camera_count > 1024)
    in.fail(std::to_string(images) + " images for " + std::to_string(camera_count) +
            " cameras (a positive multiple, at most 1024 per camera)");
  const std::uint32_t per_camera = images / camera_count;
  std::vector<cv::Size> sizes(camera_count);
  for (std::uint32_t k = 0; k < images; ++k) {
    pipeline::CameraImages& camera = set.cameras[k / per_camera];
    const std::string image = "image " + std::to_string(k);
    camera.stamps_ns.push_back(stampNs(in));
    in.string("image frame_id");
    const auto height = in.get<std::uint32_t>();
    const auto width = in.get<std::uint32_t>();
    const std::string encoding = in.string("image encoding");
    const auto big_endian = in.get<std::uint8_t>();
    const auto step = in.get<std::uint32_t>();
    const auto length = in.get<std::uint32_t>();
    const std::string_view data = in.take(length, "image data");
    const int depth = encoding == "mono8" ? CV_8U : encoding == "mono16" ? CV_16U : -1;
    if (depth < 0) in.fail(image + ": encoding '" + encoding.substr(0, 32) + "' is not mono8 or mono16");
    if ((camera.bit_depth > 8) != (depth == CV_16U))
      in.fail(image + ": " + encoding + " for bit_depth " + std::to_string(camera.bit_depth));
    if (depth == CV_16U && big_endian != 0) in.fail(image + ": big-endian mono16 is not supported");
    const std::uint64_t row_bytes = std::uint64_t(width) * (depth == CV_16U ? 2 : 1);
    if (height == 0 || width == 0 || height > 65535 || width > 65535 || step < row_bytes ||
        std::uint64_t(step) * height != length)
      in.fail(image + ": " + std::to_string(width) + "x" + std::to_string(height) + " step " +
              std::to_string(step) + " with " + std::to_string(length) + " data bytes");
    // Every image of a camera has its first image's size.
    cv::Size& first = sizes[k / per_camera];
    if (k % per_camera == 0) first = cv::Size(int(width), int(height));
    if (first != cv::Size(int(width), int(height)))
      in.fail(image + ": " + std::to_string(width) + "x" + std::to_string(height) +
              ", the camera's first image is " + std::to_string(first.width) + "x" +
              std::to_string(first.height));
    if (load_images) {
      const cv::Mat view(int(height), int(width), CV_MAKETYPE(depth, 1),
                         const_cast<char*>(data.data()), step);
      camera.frames.push_back(view.clone());
    }
  }
  return set;
}

McapImageSets::McapImageSets(const std::string& path) : path_(path) {
  File file(path);
  const std::uint64_t size = file.size();
  if (size < 8 || file.read(0, 8) != std::string_view(kMagic, 8))
    throw std::runtime_error(path + ": not an MCAP file (no MCAP magic at its start)");
  if (size < 8 + kRecordHeader + kFooterBody + 8 || file.read(size - 8, 8) != std::string_view(kMagic, 8))
    throw std::runtime_error(path + ": truncated or not closed (no MCAP magic at its end: was the "
                             "recording interrupted?)");

  struct Schema { std::string name; };
  struct Channel { std::string topic; bool image_sets; };
  std::map<std::uint16_t, Schema> schemas;
  std::map<std::uint16_t, Channel> channels;
  std::set<std::string> set_topics;  // topics of the image-set messages seen
  std::uint64_t message_number = 0;

  // One record (file level or inside a chunk); `chunk_offset` is the file
  // offset of the enclosing chunk record, or none.
  const auto handle = [&](std::uint8_t op, std::string_view body, const std::string& what,
                          std::uint64_t record_offset, std::uint64_t inner_offset, bool in_chunk) {
    Fields f(body, what);
    if (op == kSchema) {
      const auto id = f.le<std::uint16_t>();
      schemas[id] = {f.string()};
    } else if (op == kChannel) {
      const auto id = f.le<std::uint16_t>();
      const auto schema_id = f.le<std::uint16_t>();
      const std::string topic = f.string();
      const std::string encoding = f.string();
      const auto schema = schemas.find(schema_id);
      const bool image_sets = schema != schemas.end() && schema->second.name == "sl_msgs/msg/ImageSet";
      if (image_sets && encoding != "cdr")
        f.fail("channel " + topic + ": image sets encoded as '" + encoding + "', not cdr");
      channels[id] = {topic, image_sets};
    } else if (op == kMessage) {
      ++message_number;
      const auto channel_id = f.le<std::uint16_t>();
      const auto channel = channels.find(channel_id);
      if (channel == channels.end())
        f.fail("message " + std::to_string(message_number) + " on channel " +
               std::to_string(channel_id) + ", which no channel record before it defines");
      if (!channel->second.image_sets) return;
      f.le<std::uint32_t>();  // sequence
      f.le<std::uint64_t>();  // log time
      f.le<std::uint64_t>();  // publish time
      set_topics.insert(channel->second.topic);
      const std::string message = what + ": image set message " + std::to_string(message_number);
      sets_.push_back({decodeImageSetCdr(f.rest(), message, false), record_offset, inner_offset,
                       in_chunk, message_number});
    }
  };

  std::uint64_t offset = 8;
  bool footer = false, data_end = false;
  for (std::uint64_t number = 1; !footer; ++number) {
    std::string what = path + ": record " + std::to_string(number) + " at byte " + std::to_string(offset);
    if (offset + kRecordHeader > size - 8)
      throw std::runtime_error(what + ": the file ends before its footer (truncated)");
    const std::string header_bytes = file.read(offset, kRecordHeader);  // Fields holds a view
    Fields header(header_bytes, what);
    const auto op = header.le<std::uint8_t>();
    const auto length = header.le<std::uint64_t>();
    what = path + ": record " + std::to_string(number) + " (" + opName(op) + " at byte " +
           std::to_string(offset) + ")";
    if (length > size - 8 - offset - kRecordHeader)
      throw std::runtime_error(what + ": length " + std::to_string(length) +
                               " runs past the end of the file (truncated or corrupt)");
    const std::uint64_t body_offset = offset + kRecordHeader;
    if (op == kFooter) {
      if (body_offset + length != size - 8 || length != kFooterBody)
        throw std::runtime_error(what + ": not the last record before the closing magic");
      footer = true;
    } else if (op == kDataEnd) {
      data_end = true;  // the summary section follows: repeats of schemas/channels, indexes
    } else if (data_end) {
      // summary records: skipped
    } else if (op == kSchema || op == kChannel) {
      if (length > kMaxSmallRecord)
        throw std::runtime_error(what + ": " + std::to_string(length) + " bytes, more than " +
                                 std::to_string(kMaxSmallRecord));
      handle(op, file.read(body_offset, length), what, offset, 0, false);
    } else if (op == kMessage) {
      // Only an image set's message is read whole.
      if (length < kMessagePrefix) throw std::runtime_error(what + ": shorter than a message's fields");
      const std::string channel_bytes = file.read(body_offset, 2);
      Fields prefix(channel_bytes, what);
      const auto channel = channels.find(prefix.le<std::uint16_t>());
      if (channel != channels.end() && !channel->second.image_sets) {
        ++message_number;
      } else {
        handle(op, file.read(body_offset, length), what, offset, 0, false);
      }
    } else if (op == kChunk) {
      const std::string records = chunkRecords(file.read(body_offset, length), what);
      std::uint64_t inner = 0;
      for (std::uint64_t k = 1; inner < records.size(); ++k) {
        const std::string inner_what = what + ": inner record " + std::to_string(k);
        const Record r = recordAt(records, inner, inner_what);
        handle(r.op, r.body, inner_what, offset, inner, true);
        inner += kRecordHeader + r.body.size();
      }
    }
    offset = body_offset + length;
  }
  if (sets_.empty()) {
    std::string topics;
    for (const auto& [id, channel] : channels) topics += (topics.empty() ? "" : ", ") + channel.topic;
    throw std::runtime_error(
        path + ": holds no image sets (no sl_msgs/msg/ImageSet messages; topics: " +
        (topics.empty() ? "none" : topics) +
        "): record them from a daemon with dds.publish_image_sets: true by "
        "`sl_view record FILE --topics /<ns>/points,/<ns>/image_sets`");
  }
  if (set_topics.size() > 1) {
    std::string topics;
    for (const auto& t : set_topics) topics += (topics.empty() ? "" : ", ") + t;
    throw std::runtime_error(path + ": holds image sets of several topics (" + topics +
                             "); replay plays one sensor's");
  }
  topic_ = *set_topics.begin();
}

std::string McapImageSets::where(std::size_t i) const {
  return path_ + ": image set " + std::to_string(i + 1) + " (message " +
         std::to_string(sets_.at(i).message_number) + ")";
}

pipeline::ImageSet McapImageSets::load(std::size_t i) const {
  const Entry& entry = sets_.at(i);
  File file(path_);
  const std::string what = where(i);
  const std::string header_bytes = file.read(entry.record_offset, kRecordHeader);
  Fields header(header_bytes, what);
  const auto op = header.le<std::uint8_t>();
  const auto length = header.le<std::uint64_t>();
  const std::string body = file.read(entry.record_offset + kRecordHeader, length);
  std::string records;
  Record message{op, body};
  if (entry.in_chunk) {
    records = chunkRecords(body, what);
    message = recordAt(records, entry.inner_offset, what);
  }
  if (message.op != kMessage) throw std::runtime_error(what + ": changed since the file was opened");
  Fields f(message.body, what);
  f.take(kMessagePrefix);
  return decodeImageSetCdr(f.rest(), what, true);
}

}  // namespace sl::drivers
