#include "mcap_writer.h"

#include <lz4frame.h>
#include <zlib.h>
#include <zstd.h>

#include <array>
#include <cstring>
#include <iostream>
#include <stdexcept>

namespace sl::tools {

namespace {

constexpr char kMagic[] = "\x89MCAP0\r\n";  // 8 bytes

enum Op : std::uint8_t {
  kHeader = 0x01, kFooter = 0x02, kSchema = 0x03, kChannel = 0x04, kMessage = 0x05,
  kChunk = 0x06, kMessageIndex = 0x07, kChunkIndex = 0x08, kStatistics = 0x0B,
  kSummaryOffset = 0x0E, kDataEnd = 0x0F,
};

template <typename T>
void le(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));  // little-endian host
  s.append(b, sizeof(T));
}
void str(std::string& s, std::string_view v) {
  le<std::uint32_t>(s, static_cast<std::uint32_t>(v.size()));
  s.append(v);
}
std::string record(std::uint8_t op, const std::string& body) {
  std::string r;
  r.reserve(9 + body.size());
  r.push_back(static_cast<char>(op));
  le<std::uint64_t>(r, body.size());
  r += body;
  return r;
}


}  // namespace

std::uint32_t crc32(std::string_view bytes, std::uint32_t crc) {
  // zlib's CRC-32 (IEEE 802.3, as MCAP uses), continued from `crc`.
  return static_cast<std::uint32_t>(::crc32_z(crc, reinterpret_cast<const Bytef*>(bytes.data()), bytes.size()));
}

McapWriter::McapWriter(const std::string& path, const McapWriterOptions& options)
    : path_(path), options_(options) {
  if (options.compression != "" && options.compression != "zstd" && options.compression != "lz4")
    throw std::runtime_error(path + ": unknown MCAP chunk compression '" + options.compression +
                             "' (zstd, lz4 or none)");
  file_ = std::fopen(path.c_str(), "wb");
  if (file_ == nullptr)
    throw std::runtime_error(path + ": cannot create: " + std::strerror(errno));
  put(std::string_view(kMagic, 8));
  std::string h;
  str(h, options.profile);
  str(h, options.library);
  put(record(kHeader, h));
}

McapWriter::~McapWriter() {
  try {
    close();
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
  }
}

void McapWriter::put(std::string_view bytes) {
  if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size())
    throw std::runtime_error(path_ + ": write failed: " + std::strerror(errno));
  offset_ += bytes.size();
}

std::string McapWriter::schemaRecord(std::uint16_t id) const {
  const Schema& s = schemas_.at(id - 1);
  std::string b;
  le<std::uint16_t>(b, id);
  str(b, s.name);
  str(b, s.encoding);
  str(b, s.data);
  return record(kSchema, b);
}

std::string McapWriter::channelRecord(std::uint16_t id) const {
  const Channel& c = channels_.at(id);
  std::string b;
  le<std::uint16_t>(b, id);
  le<std::uint16_t>(b, c.schema);
  str(b, c.topic);
  str(b, c.encoding);
  std::string map;
  for (const auto& [k, v] : c.metadata) {
    str(map, k);
    str(map, v);
  }
  str(b, map);
  return record(kChannel, b);
}

std::uint16_t McapWriter::addSchema(const std::string& name, const std::string& encoding,
                                    std::string_view data) {
  schemas_.push_back({name, encoding, std::string(data)});
  const auto id = static_cast<std::uint16_t>(schemas_.size());
  chunk_ += schemaRecord(id);  // in the chunk, before the messages that use it
  return id;
}

std::uint16_t McapWriter::addChannel(std::uint16_t schema_id, const std::string& topic,
                                     const std::string& message_encoding,
                                     const std::map<std::string, std::string>& metadata) {
  if (schema_id == 0 || schema_id > schemas_.size())
    throw std::runtime_error(path_ + ": channel '" + topic + "' names unknown schema " +
                             std::to_string(schema_id));
  channels_.push_back({schema_id, topic, message_encoding, metadata});
  const auto id = static_cast<std::uint16_t>(channels_.size() - 1);
  chunk_ += channelRecord(id);
  return id;
}

void McapWriter::write(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                       std::uint64_t publish_time, std::string_view data) {
  if (closed_) throw std::runtime_error(path_ + ": write after close");
  if (channel_id >= channels_.size())
    throw std::runtime_error(path_ + ": message on unknown channel " + std::to_string(channel_id));
  const bool first_in_chunk = chunk_index_.empty();
  if (first_in_chunk || log_time < chunk_start_) chunk_start_ = log_time;
  if (first_in_chunk || log_time > chunk_end_) chunk_end_ = log_time;
  chunk_index_[channel_id].emplace_back(log_time, chunk_.size());
  chunk_.push_back(static_cast<char>(kMessage));
  le<std::uint64_t>(chunk_, 2 + 4 + 8 + 8 + data.size());
  le<std::uint16_t>(chunk_, channel_id);
  le<std::uint32_t>(chunk_, sequence);
  le<std::uint64_t>(chunk_, log_time);
  le<std::uint64_t>(chunk_, publish_time);
  chunk_.append(data);
  if (message_count_ == 0 || log_time < start_time_) start_time_ = log_time;
  if (message_count_ == 0 || log_time > end_time_) end_time_ = log_time;
  ++message_count_;
  ++channel_counts_[channel_id];
  if (chunk_.size() >= options_.chunk_size) flushChunk();
}

void McapWriter::flushChunk() {
  if (chunk_.empty()) return;
  if (chunk_index_.empty()) chunk_start_ = chunk_end_ = 0;  // schemas/channels only
  std::string compressed;
  std::string_view records = chunk_;
  if (options_.compression == "zstd") {
    compressed.resize(ZSTD_compressBound(chunk_.size()));
    const std::size_t n =
        ZSTD_compress(compressed.data(), compressed.size(), chunk_.data(), chunk_.size(), 1);
    if (ZSTD_isError(n))
      throw std::runtime_error(path_ + ": zstd: " + ZSTD_getErrorName(n));
    compressed.resize(n);
    records = compressed;
  } else if (options_.compression == "lz4") {
    LZ4F_preferences_t prefs;
    std::memset(&prefs, 0, sizeof prefs);
    prefs.frameInfo.contentSize = chunk_.size();
    compressed.resize(LZ4F_compressFrameBound(chunk_.size(), &prefs));
    const std::size_t n = LZ4F_compressFrame(compressed.data(), compressed.size(), chunk_.data(),
                                             chunk_.size(), &prefs);
    if (LZ4F_isError(n)) throw std::runtime_error(path_ + ": lz4: " + LZ4F_getErrorName(n));
    compressed.resize(n);
    records = compressed;
  }
  std::string body;
  le<std::uint64_t>(body, chunk_start_);
  le<std::uint64_t>(body, chunk_end_);
  le<std::uint64_t>(body, chunk_.size());
  le<std::uint32_t>(body, crc32(chunk_));
  str(body, options_.compression);
  le<std::uint64_t>(body, records.size());
  body.append(records);
  ChunkIndex ci{};
  ci.start_time = chunk_start_;
  ci.end_time = chunk_end_;
  ci.offset = offset_;
  const std::string chunk_record = record(kChunk, body);
  ci.length = chunk_record.size();
  ci.compressed_size = records.size();
  ci.uncompressed_size = chunk_.size();
  put(chunk_record);
  const std::uint64_t index_start = offset_;
  for (const auto& [channel, entries] : chunk_index_) {
    std::string mi;
    le<std::uint16_t>(mi, channel);
    std::string array;
    for (const auto& [time, at] : entries) {
      le<std::uint64_t>(array, time);
      le<std::uint64_t>(array, at);
    }
    str(mi, array);
    ci.index_offsets[channel] = offset_;
    put(record(kMessageIndex, mi));
  }
  ci.index_length = offset_ - index_start;
  chunks_.push_back(ci);
  chunk_.clear();
  chunk_index_.clear();
}

void McapWriter::close() {
  if (closed_ || file_ == nullptr) return;
  closed_ = true;
  flushChunk();
  std::string data_end;
  le<std::uint32_t>(data_end, 0);  // data section CRC not computed
  put(record(kDataEnd, data_end));

  const std::uint64_t summary_start = offset_;
  std::string summary;
  std::vector<std::tuple<std::uint8_t, std::uint64_t, std::uint64_t>> groups;
  const auto group = [&](std::uint8_t op, const std::string& bytes) {
    if (bytes.empty()) return;
    groups.emplace_back(op, summary_start + summary.size(), bytes.size());
    summary += bytes;
  };
  std::string s;
  for (std::size_t i = 0; i < schemas_.size(); ++i) s += schemaRecord(static_cast<std::uint16_t>(i + 1));
  group(kSchema, s);
  s.clear();
  for (std::size_t i = 0; i < channels_.size(); ++i) s += channelRecord(static_cast<std::uint16_t>(i));
  group(kChannel, s);
  std::string st;
  le<std::uint64_t>(st, message_count_);
  le<std::uint16_t>(st, static_cast<std::uint16_t>(schemas_.size()));
  le<std::uint32_t>(st, static_cast<std::uint32_t>(channels_.size()));
  le<std::uint32_t>(st, 0);  // attachments
  le<std::uint32_t>(st, 0);  // metadata
  le<std::uint32_t>(st, static_cast<std::uint32_t>(chunks_.size()));
  le<std::uint64_t>(st, start_time_);
  le<std::uint64_t>(st, end_time_);
  std::string counts;
  for (const auto& [channel, n] : channel_counts_) {
    le<std::uint16_t>(counts, channel);
    le<std::uint64_t>(counts, n);
  }
  str(st, counts);
  group(kStatistics, record(kStatistics, st));
  s.clear();
  for (const auto& c : chunks_) {
    std::string b;
    le<std::uint64_t>(b, c.start_time);
    le<std::uint64_t>(b, c.end_time);
    le<std::uint64_t>(b, c.offset);
    le<std::uint64_t>(b, c.length);
    std::string map;
    for (const auto& [channel, at] : c.index_offsets) {
      le<std::uint16_t>(map, channel);
      le<std::uint64_t>(map, at);
    }
    str(b, map);
    le<std::uint64_t>(b, c.index_length);
    str(b, options_.compression);
    le<std::uint64_t>(b, c.compressed_size);
    le<std::uint64_t>(b, c.uncompressed_size);
    s += record(kChunkIndex, b);
  }
  group(kChunkIndex, s);
  const std::uint64_t summary_offset_start = summary_start + summary.size();
  for (const auto& [op, start, length] : groups) {
    std::string b;
    b.push_back(static_cast<char>(op));
    le<std::uint64_t>(b, start);
    le<std::uint64_t>(b, length);
    summary += record(kSummaryOffset, b);
  }
  std::string footer;
  footer.push_back(static_cast<char>(kFooter));
  le<std::uint64_t>(footer, 8 + 8 + 4);
  le<std::uint64_t>(footer, summary.empty() ? 0 : summary_start);
  le<std::uint64_t>(footer, summary_offset_start);
  const std::uint32_t crc = crc32(footer, crc32(summary));
  le<std::uint32_t>(footer, crc);
  put(summary);
  put(footer);
  put(std::string_view(kMagic, 8));
  if (std::fclose(file_) != 0) {
    file_ = nullptr;
    throw std::runtime_error(path_ + ": close failed: " + std::strerror(errno));
  }
  file_ = nullptr;
}

}  // namespace sl::tools
