// The conversion between rmw_fastrtps's plain service samples and
// rmw_cyclonedds's framing (sl/dds/ros2_service.h): plain bytes written here
// by hand as Fast CDR lays them out (XCDR1, alignment from the end of the
// encapsulation) become the daemon's framed request types and back, in both
// byte orders; malformed and short inputs are refused.
#include <catch2/catch.hpp>

#include <cstdint>
#include <cstring>
#include <string>

#include "sl/dds/ros2_service.h"
#include "sl_msgs/srv/SetPattern.h"
#include "sl_msgs/srv/Start.h"

using sl::dds::CdrBytes;
using sl::dds::cdrFromSample;
using sl::dds::framedFromPlainCdr;
using sl::dds::plainFromFramedCdr;
using sl::dds::sampleFromCdr;

namespace {

// A plain-CDR writer: alignment counted from the end of the encapsulation.
struct Cdr {
  explicit Cdr(bool big_endian) : big(big_endian), bytes{0x00, big_endian ? std::uint8_t{0} : std::uint8_t{1}, 0, 0} {}
  void align(std::size_t n) {
    while ((bytes.size() - 4) % n != 0) bytes.push_back(0);
  }
  void put(std::uint64_t v, std::size_t size) {
    align(size);
    for (std::size_t i = 0; i < size; ++i)
      bytes.push_back(static_cast<unsigned char>(v >> (big ? 8 * (size - 1 - i) : 8 * i)));
  }
  void str(const std::string& s) {
    put(s.size() + 1, 4);
    bytes.insert(bytes.end(), s.begin(), s.end());
    bytes.push_back(0);
  }
  void f64(double d) {
    std::uint64_t v;
    std::memcpy(&v, &d, 8);
    put(v, 8);
  }
  bool big;
  CdrBytes bytes;
};

// sl_msgs/srv/Start request, plain: pattern, count, recording, trigger,
// delay_s (8-aligned: its offset moves by 16 bytes with the header),
// start_at, cameras, motion_compensation.
CdrBytes plainStart(bool big_endian) {
  Cdr c(big_endian);
  c.str("gray_code");
  c.put(static_cast<std::uint32_t>(-3), 4);
  c.str("rec");
  c.put(2, 1);
  c.f64(0.25);
  c.put(7, 4);
  c.put(500, 4);
  c.put(2, 4);
  c.str("cam0");
  c.str("cam1");
  c.put(1, 1);
  return c.bytes;
}

}  // namespace

TEST_CASE("a plain Fast DDS request reads as the framed type with the given header") {
  for (const bool big_endian : {false, true}) {
    const CdrBytes plain = plainStart(big_endian);
    const auto framed = framedFromPlainCdr(plain, 0x0102030405060708ull, -5);
    REQUIRE(framed);
    REQUIRE(framed->size() == plain.size() + 16);
    sl_msgs_srv_dds__Start_Request_ request{};
    REQUIRE(sampleFromCdr(*framed, &request, sl_msgs_srv_dds__Start_Request__desc));
    CHECK(request.request_header_guid == 0x0102030405060708ull);
    CHECK(request.request_header_seq == -5);
    CHECK(std::string(request.pattern) == "gray_code");
    CHECK(request.count == -3);
    CHECK(std::string(request.recording) == "rec");
    CHECK(request.trigger == 2);
    CHECK(request.delay_s == 0.25);
    CHECK(request.start_at.sec == 7);
    CHECK(request.start_at.nanosec == 500u);
    REQUIRE(request.cameras._length == 2u);
    CHECK(std::string(request.cameras._buffer[1]) == "cam1");
    CHECK(request.motion_compensation == 1);

    // Back: serialized by Cyclone, the header removed, the plain bytes are
    // the ones Fast CDR writes (in this host's byte order: little-endian).
    const auto again = plainFromFramedCdr(cdrFromSample(&request, sl_msgs_srv_dds__Start_Request__desc));
    dds_sample_free(&request, &sl_msgs_srv_dds__Start_Request__desc, DDS_FREE_CONTENTS);
    REQUIRE(again);
    CHECK(*again == plainStart(false));
    CHECK(plainFromFramedCdr(*framed) == plain);
  }
}

TEST_CASE("a framed response serialized by Cyclone loses exactly its header") {
  sl_msgs_srv_dds__SetPattern_Response_ response{};
  response.request_header_guid = 42;
  response.request_header_seq = 9;
  response.success = true;
  response.code = 3;
  std::string message = "switched";
  response.message = message.data();
  const CdrBytes framed = cdrFromSample(&response, sl_msgs_srv_dds__SetPattern_Response__desc);
  const auto plain = plainFromFramedCdr(framed);
  REQUIRE(plain);
  Cdr expected(false);  // x86: little-endian
  expected.put(1, 1);
  expected.put(3, 1);
  expected.str("switched");
  CHECK(*plain == expected.bytes);
  // And read back through the framing the daemon parses.
  const auto reframed = framedFromPlainCdr(*plain, 42, 9);
  REQUIRE(reframed);
  sl_msgs_srv_dds__SetPattern_Response_ read{};
  REQUIRE(sampleFromCdr(*reframed, &read, sl_msgs_srv_dds__SetPattern_Response__desc));
  CHECK(read.request_header_guid == 42);
  CHECK(read.request_header_seq == 9);
  CHECK(read.success);
  CHECK(std::string(read.message) == "switched");
  dds_sample_free(&read, &sl_msgs_srv_dds__SetPattern_Response__desc, DDS_FREE_CONTENTS);
}

TEST_CASE("short, non-CDR and malformed samples are refused") {
  CHECK_FALSE(framedFromPlainCdr({}, 1, 1));
  CHECK_FALSE(framedFromPlainCdr({0x00, 0x01, 0x00}, 1, 1));
  CHECK_FALSE(framedFromPlainCdr({0x00, 0x01, 0x00, 0x00}, 1, 1));  // no message
  CHECK_FALSE(framedFromPlainCdr({0x00, 0x03, 0x00, 0x00, 0x00}, 1, 1));  // PL_CDR_LE
  CHECK_FALSE(framedFromPlainCdr({0x00, 0x07, 0x00, 0x00, 0x00}, 1, 1));  // XCDR2
  CHECK_FALSE(plainFromFramedCdr(CdrBytes(20, 0x00)));  // encapsulation + header, no message
  CHECK_FALSE(plainFromFramedCdr({0x01, 0x01, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17}));

  const auto check_refused = [](CdrBytes plain, const char* what) {
    INFO(what);
    const auto framed = framedFromPlainCdr(plain, 1, 1);
    REQUIRE(framed);
    sl_msgs_srv_dds__SetPattern_Request_ request{};
    CHECK_FALSE(sampleFromCdr(*framed, &request, sl_msgs_srv_dds__SetPattern_Request__desc));
  };
  Cdr truncated(false);
  truncated.str("abcdef");
  truncated.bytes.resize(truncated.bytes.size() - 3);
  check_refused(truncated.bytes, "string cut short");
  Cdr too_long(false);
  too_long.put(1000, 4);
  too_long.bytes.push_back('a');
  check_refused(too_long.bytes, "string length past the end");
  Cdr unterminated(false);
  unterminated.put(3, 4);
  for (char ch : {'a', 'b', 'c'}) unterminated.bytes.push_back(static_cast<unsigned char>(ch));
  check_refused(unterminated.bytes, "string without its terminating 0");
  check_refused({0x00, 0x01, 0x00, 0x00, 0x05}, "one byte where a string length is");

  // A Start request cut before its last field.
  CdrBytes start = plainStart(false);
  start.pop_back();
  const auto framed = framedFromPlainCdr(start, 1, 1);
  REQUIRE(framed);
  sl_msgs_srv_dds__Start_Request_ cut{};
  CHECK_FALSE(sampleFromCdr(*framed, &cut, sl_msgs_srv_dds__Start_Request__desc));
}
