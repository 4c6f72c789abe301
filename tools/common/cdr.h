// Minimal reader and writer of CDR (XCDR1, little-endian) as ROS 2 puts it
// on the wire: a 4-byte encapsulation header (0x00 0x01 = CDR_LE, 2 option
// bytes), then the fields, each aligned to its own size counted from the end
// of the header. Enough for the tools that look into samples without a
// generated type (sl_view's cloud preview, MCAP replay); no DDS involved.
#pragma once

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace sl::tools {

class CdrError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class CdrReader {
 public:
  // `what` names the sample in errors ("rt/sl/points sample").
  CdrReader(const std::uint8_t* data, std::size_t size, std::string what = "CDR sample")
      : data_(data), size_(size), what_(std::move(what)) {
    if (size < 4) fail("shorter than the 4-byte encapsulation header");
    if (data[0] != 0x00 || data[1] != 0x01)
      fail("encapsulation " + std::to_string(data[0]) + "," + std::to_string(data[1]) +
           " is not CDR little-endian (0,1)");
    pos_ = 4;
  }

  std::uint8_t u8() { return get<std::uint8_t>(); }
  bool boolean() { return get<std::uint8_t>() != 0; }
  std::uint32_t u32() { return get<std::uint32_t>(); }
  std::int32_t i32() { return get<std::int32_t>(); }
  std::uint64_t u64() { return get<std::uint64_t>(); }
  float f32() { return get<float>(); }
  double f64() { return get<double>(); }
  std::string string() {
    const std::uint32_t n = u32();  // includes the terminating NUL
    need(n);
    if (n == 0) return {};
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n - 1);
    pos_ += n;
    return s;
  }
  // A sequence<octet>: its length and a pointer into the sample (no copy).
  std::string_view bytes() {
    const std::uint32_t n = u32();
    need(n);
    std::string_view v(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return v;
  }
  std::size_t position() const { return pos_; }
  std::size_t size() const { return size_; }

 private:
  template <typename T>
  T get() {
    align(sizeof(T));
    need(sizeof(T));
    T v;
    std::memcpy(&v, data_ + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  void align(std::size_t n) { pos_ = 4 + (pos_ - 4 + n - 1) / n * n; }
  void need(std::size_t n) {
    if (pos_ > size_ || size_ - pos_ < n)
      fail("truncated at byte " + std::to_string(pos_) + " (needs " + std::to_string(n) +
           " more of " + std::to_string(size_) + ")");
  }
  [[noreturn]] void fail(const std::string& why) const { throw CdrError(what_ + ": " + why); }

  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  std::string what_;
};

class CdrWriter {
 public:
  CdrWriter() : out_{0x00, 0x01, 0x00, 0x00} {}
  void u8(std::uint8_t v) { put(v); }
  void boolean(bool v) { put(static_cast<std::uint8_t>(v ? 1 : 0)); }
  void u32(std::uint32_t v) { put(v); }
  void i32(std::int32_t v) { put(v); }
  void u64(std::uint64_t v) { put(v); }
  void f32(float v) { put(v); }
  void f64(double v) { put(v); }
  void string(std::string_view s) {
    u32(static_cast<std::uint32_t>(s.size() + 1));
    out_.insert(out_.end(), s.begin(), s.end());
    out_.push_back(0);
  }
  // Starts a sequence<octet> of n bytes; returns where to write them.
  std::uint8_t* bytes(std::size_t n) {
    u32(static_cast<std::uint32_t>(n));
    const std::size_t at = out_.size();
    out_.resize(at + n);
    return out_.data() + at;
  }
  // Pads the sample to a multiple of 4 bytes and records the padding in the
  // encapsulation options, as XCDR1 writers do; returns the sample.
  std::vector<std::uint8_t>& finish() {
    const std::size_t pad = (4 - (out_.size() - 4) % 4) % 4;
    out_.resize(out_.size() + pad, 0);
    out_[3] = static_cast<std::uint8_t>(pad);
    return out_;
  }
  std::vector<std::uint8_t>& buffer() { return out_; }

 private:
  template <typename T>
  void put(T v) {
    const std::size_t n = sizeof(T);
    out_.resize(4 + (out_.size() - 4 + n - 1) / n * n, 0);
    const std::size_t at = out_.size();
    out_.resize(at + n);
    std::memcpy(out_.data() + at, &v, n);
  }
  std::vector<std::uint8_t> out_;
};

}  // namespace sl::tools
