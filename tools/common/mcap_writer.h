// A small MCAP writer (https://mcap.dev/spec): chunked and indexed (message
// indexes, chunk indexes, statistics and summary offsets), chunks compressed
// with zstd or lz4 or not at all. With profile "ros2", schemas "ros2msg" and
// messages "cdr", `ros2 bag` and Foxglove open the files. Checked by an
// independent reader (@mcap/core) in tests/view.
//
// Not thread-safe. Errors (cannot open/write the file, unknown compression,
// unknown channel) throw std::runtime_error naming the file.
#pragma once

#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace sl::tools {

struct McapWriterOptions {
  std::string profile = "ros2";
  std::string library = "sl-sensor mcap_writer";
  std::string compression = "zstd";  // "zstd", "lz4" or "" (none)
  std::size_t chunk_size = std::size_t{4} << 20;  // a chunk is closed once it holds this much
};

class McapWriter {
 public:
  McapWriter(const std::string& path, const McapWriterOptions& options = {});
  ~McapWriter();  // closes (errors are then only printed)
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  std::uint16_t addSchema(const std::string& name, const std::string& encoding,
                          std::string_view data);
  std::uint16_t addChannel(std::uint16_t schema_id, const std::string& topic,
                           const std::string& message_encoding,
                           const std::map<std::string, std::string>& metadata = {});
  void write(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
             std::uint64_t publish_time, std::string_view data);
  // Writes the last chunk, the summary and the footer. Idempotent.
  void close();

  std::uint64_t messageCount() const { return message_count_; }
  const std::string& path() const { return path_; }

 private:
  struct ChunkIndex {
    std::uint64_t start_time, end_time, offset, length;
    std::map<std::uint16_t, std::uint64_t> index_offsets;
    std::uint64_t index_length;
    std::uint64_t compressed_size, uncompressed_size;
  };
  void flushChunk();
  void put(std::string_view bytes);
  std::string schemaRecord(std::uint16_t id) const;
  std::string channelRecord(std::uint16_t id) const;

  std::string path_;
  McapWriterOptions options_;
  std::FILE* file_ = nullptr;
  std::uint64_t offset_ = 0;
  bool closed_ = false;

  struct Schema { std::string name, encoding, data; };
  struct Channel { std::uint16_t schema; std::string topic, encoding; std::map<std::string, std::string> metadata; };
  std::vector<Schema> schemas_;    // id = index + 1
  std::vector<Channel> channels_;  // id = index

  std::string chunk_;  // uncompressed records of the open chunk
  std::uint64_t chunk_start_ = 0, chunk_end_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  std::vector<ChunkIndex> chunks_;

  std::uint64_t message_count_ = 0, start_time_ = 0, end_time_ = 0;
  std::map<std::uint16_t, std::uint64_t> channel_counts_;
};

// CRC-32 (IEEE, as zlib), continuing from `crc` (0 to start).
std::uint32_t crc32(std::string_view bytes, std::uint32_t crc = 0);

}  // namespace sl::tools
