// DLPC350 command layer, byte for byte against the Programmer's Guide
// (DLPU010): framing of section 1.2, command codes and field layouts of the
// command tables, pattern LUT entries of Table 2-65.
#include <catch2/catch.hpp>

#include "fake_dlpc350.h"

using namespace sl::drivers::dlpc350;
using sl::test::FakeDlpc350;
using sl::test::FakeDlpc350State;
using Bytes = std::vector<std::uint8_t>;

namespace {

Bytes head(const Report& r, std::size_t n) { return Bytes(r.begin(), r.begin() + n); }
bool zeroFrom(const Report& r, std::size_t from) {
  for (std::size_t i = from; i < r.size(); ++i)
    if (r[i] != 0) return false;
  return true;
}

struct Rig {
  FakeDlpc350State state;
  FakeDlpc350 fake{state};
  Dlpc350 device{fake, std::chrono::milliseconds(30)};
};

}  // namespace

TEST_CASE("write command: flags 0x40, sequence, LE length, LE command code, data") {
  Rig rig;
  rig.device.setDisplayMode(DisplayMode::kPattern);  // Display Mode Selection 0x1A1B = 1
  REQUIRE(rig.state.written.size() == 1);
  CHECK(head(rig.state.written[0], 7) == Bytes{0x40, 0x00, 0x03, 0x00, 0x1B, 0x1A, 0x01});
  CHECK(zeroFrom(rig.state.written[0], 7));
  rig.device.setPatternAction(PatternAction::kStart);  // 0x1A24 = 2, next sequence number
  CHECK(head(rig.state.written[1], 7) == Bytes{0x40, 0x01, 0x03, 0x00, 0x24, 0x1A, 0x02});
}

TEST_CASE("read command: flags 0xC0, length 2, reply decoded") {
  Rig rig;
  rig.device.setPatternSource(PatternSource::kFlash);
  CHECK(head(rig.state.written[0], 7) == Bytes{0x40, 0x00, 0x03, 0x00, 0x22, 0x1A, 0x03});
  CHECK(rig.device.patternSource() == PatternSource::kFlash);
  CHECK(head(rig.state.written[1], 6) == Bytes{0xC0, 0x01, 0x02, 0x00, 0x22, 0x1A});
  CHECK(zeroFrom(rig.state.written[1], 6));
}

TEST_CASE("every command code and payload layout") {
  Rig rig;
  auto last = [&](std::size_t n) { return head(rig.state.written.back(), n); };
  rig.device.setPowerStandby(false);
  CHECK(last(7) == Bytes{0x40, 0x00, 0x03, 0x00, 0x00, 0x02, 0x00});
  rig.device.setTriggerMode(TriggerMode::kInternalOrExternal);
  CHECK(last(7) == Bytes{0x40, 0x01, 0x03, 0x00, 0x23, 0x1A, 0x01});
  // Exposure 16667 us = 0x0000411B, frame period 33333 us = 0x00008235.
  rig.device.setExposureFramePeriod(16667, 33333);
  CHECK(last(14) == Bytes{0x40, 0x02, 0x0A, 0x00, 0x29, 0x1A, 0x1B, 0x41, 0, 0, 0x35, 0x82, 0, 0});
  CHECK(rig.device.exposureFramePeriod() == std::pair<std::uint32_t, std::uint32_t>{16667, 33333});
  // Pattern Display LUT Control: counts minus one, repeat flag.
  rig.device.setPatternConfig(PatternConfig{6, true, 6, 2});
  CHECK(last(10) == Bytes{0x40, 0x04, 0x06, 0x00, 0x31, 0x1A, 0x05, 0x01, 0x05, 0x01});
  CHECK(rig.device.patternConfig() == PatternConfig{6, true, 6, 2});
  rig.device.setLedCurrents(255, 195, 255);
  CHECK(last(9) == Bytes{0x40, 0x06, 0x05, 0x00, 0x01, 0x0B, 0xFF, 0xC3, 0xFF});
  CHECK(rig.device.ledCurrents() == std::array<std::uint8_t, 3>{255, 195, 255});
  rig.device.setLedEnables(true, false, true, false);  // bit 3 sequencer, bit 1 green
  CHECK(last(7) == Bytes{0x40, 0x08, 0x03, 0x00, 0x07, 0x1A, 0x0A});
  rig.device.setTriggerOut(1, true, triggerDelayRaw(0), triggerDelayRaw(1.072));
  CHECK(last(9) == Bytes{0x40, 0x09, 0x05, 0x00, 0x1D, 0x1A, 0x01, 0xBB, 0xC5});
  rig.device.setTriggerOut(2, false, 0xBB, 0);
  CHECK(last(8) == Bytes{0x40, 0x0A, 0x04, 0x00, 0x1E, 0x1A, 0x00, 0xBB});
  rig.device.setTriggerIn1Delay(0x12345);
  CHECK(last(10) == Bytes{0x40, 0x0B, 0x06, 0x00, 0x35, 0x1A, 0x45, 0x23, 0x01, 0x00});
  rig.device.startValidation();
  CHECK(last(7) == Bytes{0x40, 0x0C, 0x03, 0x00, 0x1A, 0x1A, 0x00});
  rig.device.setMailbox(Mailbox::kPatternLut);
  CHECK(last(7) == Bytes{0x40, 0x0D, 0x03, 0x00, 0x33, 0x1A, 0x02});
  rig.device.setMailboxOffset(5);
  CHECK(last(7) == Bytes{0x40, 0x0E, 0x03, 0x00, 0x32, 0x1A, 0x05});
  CHECK_THROWS_AS(rig.device.setMailboxOffset(128), std::invalid_argument);
  CHECK_THROWS_AS(rig.device.setPatternConfig(PatternConfig{129, true, 1, 1}),
                  std::invalid_argument);
  CHECK_THROWS_AS(rig.device.setPatternConfig(PatternConfig{1, true, 1, 65}),
                  std::invalid_argument);
}

TEST_CASE("read-only commands: version, status, images in flash") {
  Rig rig;
  const Version v = rig.device.version();
  CHECK(head(rig.state.written[0], 6) == Bytes{0xC0, 0x00, 0x02, 0x00, 0x05, 0x02});
  CHECK(Version::format(v.application) == "5.1.0");
  CHECK(Version::format(v.api) == "3.0.0");
  rig.state.hardware_status = 0x01 | 0x04 | 0x80;
  rig.state.system_status = 0x00;
  rig.state.main_status = 0x02;
  const DeviceStatus s = rig.device.status();
  CHECK(head(rig.state.written[1], 6) == Bytes{0xC0, 0x01, 0x02, 0x00, 0x0A, 0x1A});
  CHECK(head(rig.state.written[2], 6) == Bytes{0xC0, 0x02, 0x02, 0x00, 0x0B, 0x1A});
  CHECK(head(rig.state.written[3], 6) == Bytes{0xC0, 0x03, 0x02, 0x00, 0x0C, 0x1A});
  CHECK(s.sequencerRunning());
  CHECK(s.faults() ==
        "DMD reset waveform controller error; sequencer error; internal memory test failed");
  CHECK(DeviceStatus{0x01, 0x01, 0}.faults().empty());
  CHECK(rig.device.imagesInFlash() == 16);
  CHECK(head(rig.state.written[4], 6) == Bytes{0xC0, 0x04, 0x02, 0x00, 0x42, 0x1A});
}

TEST_CASE("pattern LUT entry encoding (Table 2-65)") {
  PatternLutEntry e;
  e.trigger = TriggerType::kExternalPositive;  // bits 1:0 = 1
  e.pattern_number = 2;                        // bits 7:2
  e.bit_depth = 8;                             // bits 11:8
  e.leds = kLedWhite;                          // bits 14:12 = 7
  e.buffer_swap = true;                        // bit 18
  CHECK(encodePatternLutEntry(e) == 0x047809u);
  e.invert = e.insert_black = e.trigger_out_previous = true;  // bits 16, 17, 19
  CHECK(encodePatternLutEntry(e) == 0x0F7809u);
  CHECK(decodePatternLutEntry(0x0F7809u) == e);
  PatternLutEntry fill{TriggerType::kInternal, 24, 1, kLedGreen, true};
  CHECK(encodePatternLutEntry(fill) == ((24u << 2) | (1u << 8) | (2u << 12) | (1u << 16)));
  SECTION("ranges") {
    PatternLutEntry bad;
    bad.bit_depth = 9;
    CHECK_THROWS_AS(encodePatternLutEntry(bad), std::invalid_argument);
    bad.bit_depth = 8;
    bad.pattern_number = 3;  // an 8-bit image holds patterns 0..2
    CHECK_THROWS_WITH(encodePatternLutEntry(bad), Catch::Contains("not in 0..2"));
    bad.bit_depth = 7;
    bad.pattern_number = 2;  // 24 / 7 = 3 patterns
    CHECK_NOTHROW(encodePatternLutEntry(bad));
    bad.bit_depth = 2;
    bad.pattern_number = 24;  // the fill pattern exists for 1-bit only
    CHECK_THROWS_AS(encodePatternLutEntry(bad), std::invalid_argument);
  }
}

TEST_CASE("pattern LUT upload: mailbox open, offset, multi-report data, close") {
  Rig rig;
  std::vector<PatternLutEntry> lut;
  for (int i = 0; i < 24; ++i)
    lut.push_back(PatternLutEntry{TriggerType::kInternal, i % 3, 8, kLedWhite});
  rig.device.writePatternLut(lut);
  const auto& w = rig.state.written;
  REQUIRE(w.size() == 5);  // open, offset, data (2 reports), close
  CHECK(head(w[0], 7) == Bytes{0x40, 0x00, 0x03, 0x00, 0x33, 0x1A, 0x02});
  CHECK(head(w[1], 7) == Bytes{0x40, 0x01, 0x03, 0x00, 0x32, 0x1A, 0x00});
  // 24 entries x 3 bytes = 72 data bytes + 2 command bytes = 74 = 0x4A.
  CHECK(head(w[2], 6) == Bytes{0x40, 0x02, 0x4A, 0x00, 0x34, 0x1A});
  // First entry: pattern 0, 8 bit, white = 0x007800; second pattern 1 = 0x007804.
  CHECK(head(w[2], 12) ==
        Bytes{0x40, 0x02, 0x4A, 0x00, 0x34, 0x1A, 0x00, 0x78, 0x00, 0x04, 0x78, 0x00});
  // The first report carries 58 data bytes; the second report holds the
  // remaining 14 bytes with no header, then zeros.
  Bytes all;
  for (std::size_t i = 6; i < kReportSize; ++i) all.push_back(w[2][i]);
  for (std::size_t i = 0; i < 14; ++i) all.push_back(w[3][i]);
  REQUIRE(all.size() == 72);
  for (int i = 0; i < 24; ++i) {
    const std::uint32_t word = all[3 * i] | (all[3 * i + 1] << 8) | (all[3 * i + 2] << 16);
    CHECK(decodePatternLutEntry(word) == lut[static_cast<std::size_t>(i)]);
  }
  CHECK(zeroFrom(w[3], 14));
  CHECK(head(w[4], 7) == Bytes{0x40, 0x03, 0x03, 0x00, 0x33, 0x1A, 0x00});
  REQUIRE(rig.state.mailbox_writes.size() == 1);
  CHECK(rig.state.mailbox_writes[0] == all);
}

TEST_CASE("image LUT upload, with the two-entry order of the firmware") {
  Rig rig;
  rig.device.writeImageLut({7, 8, 9});
  CHECK(head(rig.state.written[0], 7) == Bytes{0x40, 0x00, 0x03, 0x00, 0x33, 0x1A, 0x01});
  CHECK(head(rig.state.written[2], 9) == Bytes{0x40, 0x02, 0x05, 0x00, 0x34, 0x1A, 7, 8, 9});
  rig.device.writeImageLut({7, 8});
  CHECK(rig.state.mailbox_writes.back() == Bytes{8, 7});
  CHECK_THROWS_AS(rig.device.writeImageLut({}), std::invalid_argument);
}

TEST_CASE("long reply spanning two reports is reassembled") {
  Rig rig;
  const Bytes d = rig.device.read(Command::kMailboxData, 100);
  REQUIRE(d.size() == 100);
  for (int i = 0; i < 100; ++i) CHECK(d[static_cast<std::size_t>(i)] == i);
}

TEST_CASE("NACK, timeout, stale replies, unplugged device") {
  Rig rig;
  SECTION("NACK names the command") {
    rig.state.nack.insert(0x1A24);
    try {
      rig.device.setPatternAction(PatternAction::kStart);
      FAIL("no exception");
    } catch (const Dlpc350Error& e) {
      CHECK(e.kind() == Dlpc350Error::Kind::kNack);
      CHECK(std::string(e.what()) ==
            "DLPC350 PatternStartStop (USB 0x1A24): the projector rejected the command (NACK)");
    }
    rig.state.nack.insert(0x1A1B);
    CHECK_THROWS_AS(rig.device.displayMode(), Dlpc350Error);
  }
  SECTION("timeout names the command and the wait") {
    rig.state.silent.insert(0x1A1B);
    try {
      rig.device.displayMode();
      FAIL("no exception");
    } catch (const Dlpc350Error& e) {
      CHECK(e.kind() == Dlpc350Error::Kind::kTimeout);
      CHECK(std::string(e.what()) == "DLPC350 DisplayMode (USB 0x1A1B): no reply within 30 ms");
    }
  }
  SECTION("a stale reply with another sequence number is skipped") {
    Report stale{};
    stale[0] = 0xC0;
    stale[1] = 0x77;
    stale[2] = 1;
    stale[4] = 0x55;
    rig.fake.queueRaw(stale);
    rig.device.setDisplayMode(DisplayMode::kPattern);
    CHECK(rig.device.displayMode() == DisplayMode::kPattern);
    CHECK(rig.device.staleReplies() == 1);  // read and dropped before the request
    CHECK(rig.device.sequenceMismatches() == 0);
  }
  SECTION("unplugged: device error with the command name") {
    rig.state.unplugged = true;
    try {
      rig.device.setPatternAction(PatternAction::kStop);
      FAIL("no exception");
    } catch (const Dlpc350Error& e) {
      CHECK(e.kind() == Dlpc350Error::Kind::kDevice);
      CHECK_THAT(e.what(), Catch::StartsWith("DLPC350 PatternStartStop (USB 0x1A24): fake: "
                                             "device unplugged"));
    }
  }
  SECTION("a reply shorter than the command's data is a protocol error") {
    try {
      rig.device.read(Command::kDisplayMode, 4);
      FAIL("no exception");
    } catch (const Dlpc350Error& e) {
      CHECK(e.kind() == Dlpc350Error::Kind::kProtocol);
      CHECK_THAT(e.what(), Catch::Contains("reply has 1 data bytes, expected 4"));
    }
  }
}

TEST_CASE("validation status bits as text") {
  CHECK(ValidationStatus{0x00}.valid());
  CHECK(ValidationStatus{0x80}.busy());
  const ValidationStatus bad{0x1F};
  CHECK_FALSE(bad.valid());
  CHECK(bad.errors() ==
        "selected exposure or frame period settings are invalid; selected pattern numbers in the "
        "LUT are invalid");
  CHECK(bad.warnings() ==
        "continuous trigger out 1 request or overlapping black sectors; post vector was not "
        "inserted prior to an external triggered vector; frame period or exposure difference is "
        "less than 230 us");
  CHECK(ValidationStatus{0x04}.valid());
}

TEST_CASE("trigger delay conversion: 107.2 ns steps around 0xBB") {
  CHECK(triggerDelayRaw(0) == 0xBB);
  CHECK(triggerDelayRaw(-20.05) == 0x00);
  CHECK(triggerDelayRaw(2.787) == 0xD5);
  CHECK_THROWS_AS(triggerDelayRaw(3.0), std::invalid_argument);
  CHECK_THROWS_AS(triggerDelayRaw(-21.0), std::invalid_argument);
}

// Point 5 of issue 19: the reply to the one outstanding request is taken
// whatever its sequence byte; both device behaviours work.
TEST_CASE("sequence numbers: echoing device and TI-API-style device") {
  FakeDlpc350State state;
  std::vector<std::string> logged;
  auto log = [&](const std::string& m) { logged.push_back(m); };
  auto exercise = [](Dlpc350& device) {
    device.setDisplayMode(DisplayMode::kPattern);
    CHECK(device.displayMode() == DisplayMode::kPattern);
    device.setPatternConfig(PatternConfig{6, true, 6, 2});
    CHECK(device.patternConfig() == PatternConfig{6, true, 6, 2});
    device.setLedCurrents(1, 2, 3);
    CHECK(device.ledCurrents() == std::array<std::uint8_t, 3>{1, 2, 3});
    CHECK(Version::format(device.version().application) == "5.1.0");
  };
  SECTION("echo: no mismatch, nothing logged") {
    FakeDlpc350 fake(state);
    Dlpc350 device(fake, std::chrono::milliseconds(30), log);
    exercise(device);
    CHECK(device.sequenceMismatches() == 0);
    CHECK(logged.empty());
  }
  SECTION("TI API style (own write counter, 0 on reads): every read still answers, logged once") {
    state.sequence_style = sl::test::FakeSequenceStyle::kTiApi;
    state.device_sequence = 200;  // nothing like the host's numbers
    FakeDlpc350 fake(state);
    Dlpc350 device(fake, std::chrono::milliseconds(30), log);
    exercise(device);
    exercise(device);
    CHECK(device.sequenceMismatches() >= 8);
    REQUIRE(logged.size() == 1);
    CHECK_THAT(logged[0], Catch::Contains("DLPC350 DisplayMode: reply carries sequence 200 for "
                                          "request 0"));
  }
  SECTION("an echoing device's late reply to an earlier request is skipped") {
    FakeDlpc350 fake(state);
    Dlpc350 device(fake, std::chrono::milliseconds(30), log);
    exercise(device);  // 8 echoed replies: the device echoes
    Report late{};
    late[0] = 0xC0;
    late[1] = 0x03;  // an old request's number
    late[2] = 1;
    late[4] = 0x00;  // would read as video mode
    state.late = late;
    CHECK(device.displayMode() == DisplayMode::kPattern);
    CHECK(device.staleReplies() == 1);
    CHECK(logged.empty());
  }
}

TEST_CASE("LED PWM polarity command 0x1A05: one byte, read back") {
  Rig rig;
  rig.device.setLedPwmInverted(false);
  CHECK(head(rig.state.written[0], 7) == Bytes{0x40, 0x00, 0x03, 0x00, 0x05, 0x1A, 0x00});
  CHECK_FALSE(rig.device.ledPwmInverted());
  CHECK(head(rig.state.written[1], 6) == Bytes{0xC0, 0x01, 0x02, 0x00, 0x05, 0x1A});
  rig.device.setLedPwmInverted(true);
  CHECK(head(rig.state.written[2], 7) == Bytes{0x40, 0x02, 0x03, 0x00, 0x05, 0x1A, 0x01});
  CHECK(rig.device.ledPwmInverted());
}
