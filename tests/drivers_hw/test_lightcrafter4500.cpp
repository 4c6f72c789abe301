// LightCrafter4500Projector above a fake DLPC350: start-up, sequence upload
// (pattern LUT, image LUT, LUT control, validation), refusals with the
// projector's reason, errors naming the command, reconnect after unplugging.
#include <algorithm>
#include <catch2/catch.hpp>

#include "fake_dlpc350.h"
#include "sl/drivers/lightcrafter4500.h"

using namespace sl::drivers;
using sl::test::FakeDlpc350;
using sl::test::FakeDlpc350State;
namespace dl = sl::drivers::dlpc350;
using Bytes = std::vector<std::uint8_t>;

namespace {

LightCrafter4500Sequence horizontal() {
  // As sl_sensor's psp_tpu_horizontal: images 7, 8, channels G/R/B planes.
  LightCrafter4500Sequence s;
  s.name = "3+3_horizontal";
  for (int image : {7, 8})
    for (int channel = 0; channel < 3; ++channel) s.patterns.push_back({image, channel, 8, false});
  s.exposure_us = 16667;
  s.frame_period_us = 16667;
  s.first_trigger = dl::TriggerType::kExternalPositive;
  return s;
}

LightCrafter4500Config config() {
  LightCrafter4500Config c;
  c.sequences = {horizontal()};
  c.reply_timeout = std::chrono::milliseconds(30);
  c.validation_poll = std::chrono::milliseconds(1);
  c.validation_timeout = std::chrono::milliseconds(200);
  c.power_up_timeout = std::chrono::milliseconds(2000);
  return c;
}

struct Rig {
  FakeDlpc350State state;
  LightCrafter4500Projector::TransportFactory factory() {
    return [this]() -> std::unique_ptr<dl::HidTransport> {
      if (state.unplugged) throw dl::HidError("LightCrafter 4500 (USB 0451:6401) not found");
      return std::make_unique<FakeDlpc350>(state);
    };
  }
  // Commands written since `from` (the first report of each message).
  std::vector<std::uint16_t> commands(std::size_t from = 0) const {
    std::vector<std::uint16_t> out;
    std::size_t skip = 0;
    for (std::size_t i = from; i < state.written.size(); ++i) {
      if (skip > 0) {
        --skip;
        continue;
      }
      const auto& r = state.written[i];
      const std::size_t len = r[2] | (r[3] << 8);
      skip = (4 + len + 63) / 64 - 1;
      if (!(r[0] & dl::kFlagRead)) out.push_back(static_cast<std::uint16_t>(r[4] | (r[5] << 8)));
    }
    return out;
  }
};

}  // namespace

TEST_CASE("buildUpload: buffer swap on image change, image LUT, LUT control") {
  const LightCrafter4500Upload u = buildUpload(horizontal());
  REQUIRE(u.pattern_lut.size() == 6);
  CHECK(u.image_lut == Bytes{7, 8});
  CHECK(u.config == dl::PatternConfig{6, true, 6, 2});
  CHECK(u.pattern_lut[0].trigger == dl::TriggerType::kExternalPositive);
  CHECK(u.pattern_lut[1].trigger == dl::TriggerType::kInternal);
  CHECK(u.pattern_lut[0].buffer_swap);
  CHECK_FALSE(u.pattern_lut[1].buffer_swap);
  CHECK(u.pattern_lut[3].buffer_swap);
  CHECK(u.pattern_lut[5].pattern_number == 2);
  CHECK(u.pattern_lut[5].leds == dl::kLedWhite);
}

TEST_CASE("validateSequence refuses impossible sequences offline") {
  LightCrafter4500Sequence s = horizontal();
  s.exposure_us = 16600;  // differs from the period by only 67 us
  CHECK_THROWS_WITH(validateSequence(s), Catch::Contains("exceed it by more than 230 us"));
  s = horizontal();
  s.exposure_us = 4000;  // below the 8-bit minimum
  s.frame_period_us = 4000;
  CHECK_THROWS_WITH(validateSequence(s), Catch::Contains("8333 us a 8-bit pattern needs"));
  s = horizontal();
  s.patterns[2].channel = 3;
  CHECK_THROWS_WITH(validateSequence(s), Catch::Contains("'3+3_horizontal': pattern 2"));
  s = horizontal();
  s.patterns.clear();
  CHECK_THROWS_AS(validateSequence(s), std::invalid_argument);
}

TEST_CASE("start-up: version, leaves standby, status, pattern mode, LEDs, trigger out") {
  Rig rig;
  rig.state.standby_polls = 2;
  LightCrafter4500Projector p(config(), rig.factory());
  CHECK(p.firmwareVersion() == "5.1.0");
  CHECK(rig.state.opens == 1);
  CHECK(rig.commands() ==
        std::vector<std::uint16_t>{0x0200, 0x1A1B, 0x1A24, 0x1A05, 0x0B01, 0x1A07, 0x1A1D});
  CHECK(rig.state.registers[0x0200] == Bytes{0});              // normal operation
  CHECK(rig.state.registers[0x1A05] == Bytes{0});              // LED PWM polarity normal
  CHECK(rig.state.registers[0x1A1B] == Bytes{1});              // pattern display mode
  CHECK(rig.state.registers[0x0B01] == Bytes{255, 195, 255});  // 255 - {0, 60, 0}
  CHECK(rig.state.registers[0x1A07] == Bytes{0x08});           // sequencer drives the LEDs
  CHECK(rig.state.registers[0x1A1D] == Bytes{0x00, 0xBB, 0xBB});
  const auto seqs = p.sequences();
  REQUIRE(seqs.size() == 3);
  CHECK(seqs[0].name == "3+3_horizontal");
  CHECK(seqs[0].frame_count == 6);
  CHECK(seqs[1].name == "white");
  CHECK(seqs[2].name == "black");
}

TEST_CASE("LED PWM polarity (0x1A05) set explicitly at connect and read back") {
  Rig rig;
  REQUIRE(rig.state.led_pwm_default == 1);  // the fake powers up inverted
  SECTION("normal, as SLStudio and TI's GUI set it; currents still 255 - value") {
    LightCrafter4500Projector p(config(), rig.factory());
    CHECK(rig.state.registers[0x1A05] == Bytes{0});
    CHECK(rig.state.registers[0x0B01] == Bytes{255, 195, 255});
    // The polarity is written before the currents (the order SLStudio uses).
    const auto cmds = rig.commands();
    const auto at = [&](std::uint16_t c) {
      return std::find(cmds.begin(), cmds.end(), c) - cmds.begin();
    };
    CHECK(at(0x1A05) < at(0x0B01));
  }
  SECTION("configured inverted") {
    LightCrafter4500Config c = config();
    c.led_pwm_polarity_inverted = true;
    LightCrafter4500Projector p(c, rig.factory());
    CHECK(rig.state.registers[0x1A05] == Bytes{1});
  }
  SECTION("a device that does not keep it is an error naming the command") {
    rig.state.led_pwm_stuck = true;
    CHECK_THROWS_WITH(LightCrafter4500Projector(config(), rig.factory()),
                      Catch::Contains("LED PWM polarity (DLPC350 LedPwmPolarity, USB 0x1A05) reads "
                                      "back inverted after setting it normal"));
  }
  SECTION("set again on every reconnect") {
    LightCrafter4500Projector p(config(), rig.factory());
    rig.state.registers.erase(0x1A05);  // power-cycled: back to its default
    rig.state.unplugged = true;
    CHECK_THROWS(p.stop());
    rig.state.unplugged = false;
    p.stop();  // reconnects
    CHECK(rig.state.opens == 2);
    CHECK(rig.state.registers[0x1A05] == Bytes{0});
  }
}

TEST_CASE("a device numbering replies TI-API style works and is logged once") {
  Rig rig;
  rig.state.sequence_style = sl::test::FakeSequenceStyle::kTiApi;
  std::vector<std::string> logged;
  LightCrafter4500Projector p(config(), rig.factory(),
                              [&](const std::string& m) { logged.push_back(m); });
  p.select("3+3_horizontal");  // many writes and reads (validation polls)
  p.start(0);
  p.stop();
  CHECK(p.firmwareVersion() == "5.1.0");
  REQUIRE(logged.size() == 1);
  CHECK_THAT(logged[0], Catch::Contains("does not echo sequence numbers"));
}

TEST_CASE("select uploads and validates; start and stop") {
  Rig rig;
  LightCrafter4500Projector p(config(), rig.factory());
  const std::size_t from = rig.state.written.size();
  rig.state.validation_busy_polls = 3;
  p.select("3+3_horizontal");
  CHECK(rig.commands(from) == std::vector<std::uint16_t>{0x1A24, 0x1A22, 0x1A23, 0x1A29, 0x1A31,
                                                         0x1A33, 0x1A32, 0x1A34, 0x1A33, 0x1A33,
                                                         0x1A32, 0x1A34, 0x1A33, 0x1A1A});
  CHECK(rig.state.registers[0x1A22] == Bytes{3});  // flash
  CHECK(rig.state.registers[0x1A23] == Bytes{1});  // internal / external trigger
  CHECK(rig.state.registers[0x1A29] == Bytes{0x1B, 0x41, 0, 0, 0x1B, 0x41, 0, 0});
  CHECK(rig.state.registers[0x1A31] == Bytes{5, 1, 5, 1});
  REQUIRE(rig.state.mailbox_writes.size() == 2);
  // Pattern LUT: entry 0 external positive + buffer swap, G plane of image 7.
  CHECK(rig.state.mailbox_writes[0] == Bytes{0x01, 0x78, 0x04, 0x04, 0x78, 0x00, 0x08, 0x78, 0x00,
                                             0x00, 0x78, 0x04, 0x04, 0x78, 0x00, 0x08, 0x78, 0x00});
  CHECK(rig.state.mailbox_writes[1] == Bytes{8, 7});  // two entries go out reversed
  CHECK(p.lastValidationWarnings().empty());

  const std::size_t before_start = rig.state.written.size();
  p.start(0);
  CHECK(rig.commands(before_start) == std::vector<std::uint16_t>{0x1A24});
  CHECK(rig.state.registers[0x1A24] == Bytes{2});
  CHECK_THROWS_AS(p.select("white"), std::logic_error);
  p.stop();
  CHECK(rig.state.registers[0x1A24] == Bytes{0});

  SECTION("selecting the uploaded sequence again sends nothing new") {
    const std::size_t n = rig.state.written.size();
    p.select("3+3_horizontal");
    CHECK(rig.state.written.size() == n);
  }
  SECTION("black is the 1-bit fill pattern 24, white the same inverted") {
    // dlpc350::fillPattern cites the source (Programmer's Guide pattern
    // number mapping; TI API v4.0.0 comment vs code; sl_sensor's correction).
    auto lutWord = [&] {
      const auto& m = rig.state.mailbox_writes[rig.state.mailbox_writes.size() - 2];  // pattern LUT
      REQUIRE(m.size() == 3);
      return dl::decodePatternLutEntry(m[0] | (m[1] << 8) | (m[2] << 16));
    };
    p.select("black");
    const auto black = lutWord();
    CHECK(black.pattern_number == 24);
    CHECK(black.bit_depth == 1);
    CHECK_FALSE(black.invert);
    CHECK_FALSE(black.insert_black);
    p.select("white");
    const auto white = lutWord();
    CHECK(white.pattern_number == 24);
    CHECK(white.bit_depth == 1);
    CHECK(white.invert);
    CHECK(dl::encodePatternLutEntry(white) == dl::encodePatternLutEntry(black) + (1u << 16));
  }
  SECTION("unknown names") { CHECK_THROWS_AS(p.select("nope"), std::invalid_argument); }
}

TEST_CASE("a sequence the projector refuses is reported with its reason") {
  Rig rig;
  LightCrafter4500Projector p(config(), rig.factory());
  rig.state.validation_bits = 0x01 | 0x10;
  CHECK_THROWS_WITH(p.select("3+3_horizontal"),
                    "lightcrafter4500: sequence '3+3_horizontal' refused by the projector "
                    "(DLPC350 ValidateLut, USB 0x1A1A): "
                    "selected exposure or frame period settings are invalid");
  CHECK_THROWS_AS(p.start(0), std::runtime_error);  // still refused: uploads again, fails again
  rig.state.validation_bits = 0x04;                 // a warning only
  p.select("3+3_horizontal");
  CHECK(p.lastValidationWarnings() ==
        "continuous trigger out 1 request or overlapping black sectors");
  SECTION("validation that never finishes") {
    rig.state.validation_busy_polls = 1000000;
    CHECK_THROWS_WITH(p.select("white"), Catch::Contains("did not finish within 200 ms"));
  }
  SECTION("images missing from flash") {
    rig.state.images_in_flash = 8;
    LightCrafter4500Config c = config();
    c.sequences[0].name = "other";
    LightCrafter4500Projector q(c, rig.factory());
    CHECK_THROWS_WITH(q.select("other"),
                      Catch::Contains("uses flash image 8 but the projector's flash holds 8"));
  }
}

TEST_CASE("device errors name the command; unplug and reconnect") {
  Rig rig;
  SECTION("missing device at start-up") {
    rig.state.unplugged = true;
    CHECK_THROWS_WITH(LightCrafter4500Projector(config(), rig.factory()),
                      Catch::Contains("not found"));
  }
  SECTION("device fault reported at start-up") {
    rig.state.hardware_status = 0x03;
    CHECK_THROWS_WITH(LightCrafter4500Projector(config(), rig.factory()),
                      "lightcrafter4500: the projector reports: incompatible controller or DMD");
  }
  SECTION("NACK on start") {
    LightCrafter4500Projector p(config(), rig.factory());
    p.select("3+3_horizontal");
    rig.state.nack.insert(0x1A24);
    CHECK_THROWS_WITH(p.start(0),
                      Catch::Contains("PatternStartStop (USB 0x1A24)") && Catch::Contains("NACK"));
  }
  SECTION("timeout on start") {
    LightCrafter4500Projector p(config(), rig.factory());
    p.select("3+3_horizontal");
    rig.state.silent.insert(0x1A24);
    CHECK_THROWS_WITH(p.start(0), "DLPC350 PatternStartStop (USB 0x1A24): no reply within 30 ms");
  }
  SECTION("unplugged mid-run, then plugged in again") {
    LightCrafter4500Projector p(config(), rig.factory());
    p.select("3+3_horizontal");
    p.start(0);
    rig.state.unplugged = true;
    CHECK_THROWS_WITH(p.stop(),
                      Catch::Contains("PatternStartStop") && Catch::Contains("unplugged"));
    CHECK_THROWS_WITH(p.start(0), Catch::Contains("not found"));  // reopen fails
    rig.state.unplugged = false;
    const std::size_t from = rig.state.written.size();
    p.start(0);  // reopens, initialises, uploads the selected sequence again, starts
    CHECK(rig.state.opens == 2);
    const auto cmds = rig.commands(from);
    CHECK(std::count(cmds.begin(), cmds.end(), 0x1A31) == 1);
    CHECK(cmds.back() == 0x1A24);
    CHECK(rig.state.registers[0x1A24] == Bytes{2});
  }
}

namespace {

// The 24-bit pattern LUT entries of a LutData payload.
std::vector<dl::PatternLutEntry> lutEntries(const Bytes& payload) {
  std::vector<dl::PatternLutEntry> out;
  for (std::size_t at = 0; at + 3 <= payload.size(); at += 3)
    out.push_back(
        dl::decodePatternLutEntry(payload[at] | (payload[at + 1] << 8) | (payload[at + 2] << 16)));
  return out;
}

}  // namespace

TEST_CASE(
    "projectSingle holds one pattern: one-entry LUT, internal trigger, repeat; start restores") {
  Rig rig;
  LightCrafter4500Projector p(config(), rig.factory());
  REQUIRE(p.canProjectSingle());
  CHECK_THROWS_WITH(p.projectSingle(0), Catch::Contains("lightcrafter4500: projectSingle(0)") &&
                                            Catch::Contains("no sequence selected"));
  p.select("3+3_horizontal");
  const Bytes full_lut = rig.state.mailbox_writes[0];
  const std::size_t from = rig.state.written.size();
  const std::size_t mailbox_from = rig.state.mailbox_writes.size();
  rig.state.validation_busy_polls = 2;
  p.projectSingle(4);  // image 8, R plane
  // Stop, flash source, trigger mode, exposure, LUT control, pattern LUT,
  // image LUT, validate (polled), start.
  CHECK(rig.commands(from) == std::vector<std::uint16_t>{0x1A24, 0x1A22, 0x1A23, 0x1A29, 0x1A31,
                                                         0x1A33, 0x1A32, 0x1A34, 0x1A33, 0x1A33,
                                                         0x1A32, 0x1A34, 0x1A33, 0x1A1A, 0x1A24});
  CHECK(rig.state.registers[0x1A31] == Bytes{0, 1, 0, 0});  // 1 entry, repeat, 1 image
  CHECK(rig.state.registers[0x1A29] == Bytes{0x1B, 0x41, 0, 0, 0x1B, 0x41, 0, 0});
  REQUIRE(rig.state.mailbox_writes.size() == mailbox_from + 2);
  // Internal trigger (0), pattern 1 (bits 7:2 = 0x04), 8 bits, white LEDs, buffer swap.
  CHECK(rig.state.mailbox_writes[mailbox_from] == Bytes{0x04, 0x78, 0x04});
  const auto entries = lutEntries(rig.state.mailbox_writes[mailbox_from]);
  REQUIRE(entries.size() == 1);
  CHECK(entries[0].trigger == dl::TriggerType::kInternal);
  CHECK(entries[0].pattern_number == 1);
  CHECK(entries[0].bit_depth == 8);
  CHECK(entries[0].buffer_swap);
  CHECK(rig.state.mailbox_writes[mailbox_from + 1] == Bytes{8});
  CHECK(rig.state.registers[0x1A24] == Bytes{2});  // started

  SECTION("the same pattern again sends nothing; another pattern uploads its entry") {
    const std::size_t n = rig.state.written.size();
    p.projectSingle(4);
    CHECK(rig.state.written.size() == n);
    p.projectSingle(0);
    CHECK(rig.state.mailbox_writes.back() == Bytes{7});
    CHECK(lutEntries(rig.state.mailbox_writes[rig.state.mailbox_writes.size() - 2]) ==
          std::vector<dl::PatternLutEntry>{
              {dl::TriggerType::kInternal, 0, 8, dl::kLedWhite, false, false, true, false}});
  }
  SECTION("stop ends it; a normal start uploads the full sequence again") {
    p.stop();
    CHECK(rig.state.registers[0x1A24] == Bytes{0});
    const std::size_t before = rig.state.written.size();
    p.start(0);
    const auto cmds = rig.commands(before);
    CHECK(std::count(cmds.begin(), cmds.end(), 0x1A31) == 1);
    CHECK(cmds.back() == 0x1A24);
    CHECK(rig.state.registers[0x1A31] == Bytes{5, 1, 5, 1});
    CHECK(rig.state.mailbox_writes[rig.state.mailbox_writes.size() - 2] == full_lut);
    CHECK(rig.state.mailbox_writes.back() == Bytes{8, 7});
    CHECK(rig.state.registers[0x1A24] == Bytes{2});
    CHECK_THROWS_WITH(p.projectSingle(0), Catch::Contains("a sequence is running"));
    p.stop();
    const std::size_t n = rig.state.written.size();
    p.projectSingle(4);  // stop() ended the held pattern: shown afresh
    CHECK(rig.state.written.size() > n);
  }
  SECTION("a start without stop also restores the full sequence") {
    p.start(0);
    CHECK(rig.state.registers[0x1A31] == Bytes{5, 1, 5, 1});
    CHECK(rig.state.mailbox_writes[rig.state.mailbox_writes.size() - 2] == full_lut);
  }
  SECTION("an index outside the sequence") {
    CHECK_THROWS_AS(p.projectSingle(6), std::out_of_range);
    CHECK_THROWS_AS(p.projectSingle(-1), std::out_of_range);
  }
}

TEST_CASE(
    "projectSingle: refusals and device faults name the projector, the pattern and the command") {
  Rig rig;
  LightCrafter4500Projector p(config(), rig.factory());
  p.select("3+3_horizontal");
  SECTION("validation refuses the entry") {
    rig.state.validation_bits = 0x02;
    CHECK_THROWS_WITH(
        p.projectSingle(2),
        "lightcrafter4500: pattern 2 of sequence '3+3_horizontal' refused by the "
        "projector (DLPC350 ValidateLut, USB 0x1A1A): selected pattern numbers in the "
        "LUT are invalid");
    CHECK(rig.state.registers[0x1A24] == Bytes{0});  // not started
    rig.state.validation_bits = 0;
    p.projectSingle(2);  // tried again: not taken for shown
    CHECK(rig.state.registers[0x1A24] == Bytes{2});
  }
  SECTION("validation that never finishes") {
    rig.state.validation_busy_polls = 1000000;
    CHECK_THROWS_WITH(p.projectSingle(1),
                      Catch::Contains("lightcrafter4500: validation of pattern 1") &&
                          Catch::Contains("ValidateLut") &&
                          Catch::Contains("did not finish within 200 ms"));
  }
  SECTION("PatternStartStop is refused") {
    rig.state.nack.insert(0x1A24);
    CHECK_THROWS_WITH(p.projectSingle(3),
                      "lightcrafter4500: showing pattern 3 of sequence '3+3_horizontal': DLPC350 "
                      "PatternStartStop (USB 0x1A24): the projector rejected the command (NACK)");
  }
  SECTION("unplugged: reported, then reopened by the next call") {
    rig.state.unplugged = true;
    CHECK_THROWS_WITH(p.projectSingle(0), Catch::Contains("lightcrafter4500: showing pattern 0") &&
                                              Catch::Contains("unplugged"));
    CHECK_THROWS_WITH(p.projectSingle(0),
                      "lightcrafter4500: showing pattern 0 of sequence "
                      "'3+3_horizontal': LightCrafter 4500 (USB 0451:6401) "
                      "not found");
    rig.state.unplugged = false;
    p.projectSingle(0);
    CHECK(rig.state.opens == 2);
    CHECK(rig.state.mailbox_writes.back() == Bytes{7});
    CHECK(rig.state.registers[0x1A24] == Bytes{2});
  }
}
