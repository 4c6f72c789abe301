#include <algorithm>
#include <cstring>

#include "sl/drivers/versavis.h"

namespace sl::drivers::rosserial {

namespace {

void putU16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
void putU32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void putString(std::vector<std::uint8_t>& out, const std::string& s) {
  putU32(out, static_cast<std::uint32_t>(s.size()));
  out.insert(out.end(), s.begin(), s.end());
}

// Little-endian reader over a message; ok() turns false on any overrun.
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> d) : d_(d) {}
  std::uint64_t uint(int bytes) {
    if (at_ + static_cast<std::size_t>(bytes) > d_.size()) {
      ok_ = false;
      return 0;
    }
    std::uint64_t v = 0;
    for (int i = 0; i < bytes; ++i) v |= std::uint64_t{d_[at_ + i]} << (8 * i);
    at_ += static_cast<std::size_t>(bytes);
    return v;
  }
  std::string string() {
    const auto n = uint(4);
    if (!ok_ || at_ + n > d_.size()) {
      ok_ = false;
      return {};
    }
    std::string s(d_.begin() + static_cast<std::ptrdiff_t>(at_),
                  d_.begin() + static_cast<std::ptrdiff_t>(at_ + n));
    at_ += n;
    return s;
  }
  bool ok() const { return ok_; }
  bool atEnd() const { return at_ == d_.size(); }

 private:
  std::span<const std::uint8_t> d_;
  std::size_t at_ = 0;
  bool ok_ = true;
};

}  // namespace

std::vector<std::uint8_t> encodeFrame(std::uint16_t topic_id,
                                      std::span<const std::uint8_t> message) {
  std::vector<std::uint8_t> out{0xFF, 0xFE};
  const auto len = static_cast<std::uint16_t>(message.size());
  putU16(out, len);
  out.push_back(static_cast<std::uint8_t>(255 - ((out[2] + out[3]) % 256)));
  putU16(out, topic_id);
  out.insert(out.end(), message.begin(), message.end());
  unsigned sum = out[5] + out[6];
  for (auto b : message) sum += b;
  out.push_back(static_cast<std::uint8_t>(255 - (sum % 256)));
  return out;
}

void FrameParser::feed(std::span<const std::uint8_t> bytes) {
  buffer_.insert(buffer_.end(), bytes.begin(), bytes.end());
}

std::optional<Frame> FrameParser::next() {
  std::size_t at = 0;
  auto consume = [&](std::size_t n) {
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(n));
  };
  for (;;) {
    // Skip to a sync byte followed by the protocol version (or the end).
    while (at < buffer_.size() && buffer_[at] != 0xFF) ++at;
    if (at + 1 < buffer_.size() && buffer_[at + 1] != 0xFE) {
      ++at;  // a lone 0xFF: not a packet start
      continue;
    }
    garbage_ += at;
    consume(at);
    at = 0;
    if (buffer_.size() < 5) return std::nullopt;
    const std::size_t len = buffer_[2] | (std::size_t{buffer_[3]} << 8);
    if ((buffer_[2] + buffer_[3] + buffer_[4]) % 256 != 255 || len > kMaxMessage) {
      ++checksum_errors_;
      at = 1;  // resynchronise after this sync byte
      continue;
    }
    if (buffer_.size() < 8 + len) return std::nullopt;
    unsigned sum = 0;
    for (std::size_t i = 5; i < 7 + len; ++i) sum += buffer_[i];
    if ((sum + buffer_[7 + len]) % 256 != 255) {
      ++checksum_errors_;
      at = 1;
      continue;
    }
    Frame f;
    f.topic_id = static_cast<std::uint16_t>(buffer_[5] | (buffer_[6] << 8));
    f.message.assign(buffer_.begin() + 7, buffer_.begin() + 7 + static_cast<std::ptrdiff_t>(len));
    consume(8 + len);
    return f;
  }
}

std::vector<std::uint8_t> encodeTopicInfo(const TopicInfo& info) {
  std::vector<std::uint8_t> out;
  putU16(out, info.topic_id);
  putString(out, info.topic_name);
  putString(out, info.message_type);
  putString(out, info.md5sum);
  putU32(out, static_cast<std::uint32_t>(info.buffer_size));
  return out;
}

std::optional<TopicInfo> decodeTopicInfo(std::span<const std::uint8_t> message) {
  Reader r(message);
  TopicInfo info;
  info.topic_id = static_cast<std::uint16_t>(r.uint(2));
  info.topic_name = r.string();
  info.message_type = r.string();
  info.md5sum = r.string();
  info.buffer_size = static_cast<std::int32_t>(r.uint(4));
  if (!r.ok() || !r.atEnd()) return std::nullopt;
  return info;
}

std::vector<std::uint8_t> encodeTimeNumbered(const TimeNumbered& m) {
  std::vector<std::uint8_t> out;
  putU32(out, m.secs);
  putU32(out, m.nsecs);
  putU32(out, static_cast<std::uint32_t>(m.number));
  putU32(out, static_cast<std::uint32_t>(m.number >> 32));
  return out;
}

std::optional<TimeNumbered> decodeTimeNumbered(std::span<const std::uint8_t> message) {
  Reader r(message);
  TimeNumbered m;
  m.secs = static_cast<std::uint32_t>(r.uint(4));
  m.nsecs = static_cast<std::uint32_t>(r.uint(4));
  m.number = r.uint(8);
  if (!r.ok() || !r.atEnd() || m.nsecs >= 1000000000u) return std::nullopt;
  return m;
}

std::vector<std::uint8_t> encodeTime(std::int64_t stamp_ns) {
  std::vector<std::uint8_t> out;
  putU32(out, static_cast<std::uint32_t>(stamp_ns / 1000000000));
  putU32(out, static_cast<std::uint32_t>(stamp_ns % 1000000000));
  return out;
}

std::optional<std::int64_t> decodeTime(std::span<const std::uint8_t> message) {
  Reader r(message);
  const auto secs = r.uint(4), nsecs = r.uint(4);
  if (!r.ok() || !r.atEnd()) return std::nullopt;
  return static_cast<std::int64_t>(secs) * 1000000000 + static_cast<std::int64_t>(nsecs);
}

std::vector<std::uint8_t> encodeBool(bool value) {
  return {static_cast<std::uint8_t>(value ? 1 : 0)};
}

std::optional<bool> decodeBool(std::span<const std::uint8_t> message) {
  if (message.size() != 1) return std::nullopt;
  return message[0] != 0;
}

std::vector<std::uint8_t> encodeLog(const LogMessage& m) {
  std::vector<std::uint8_t> out{m.level};
  putString(out, m.text);
  return out;
}

std::optional<LogMessage> decodeLog(std::span<const std::uint8_t> message) {
  Reader r(message);
  LogMessage m;
  m.level = static_cast<std::uint8_t>(r.uint(1));
  m.text = r.string();
  if (!r.ok() || !r.atEnd()) return std::nullopt;
  return m;
}

}  // namespace sl::drivers::rosserial
