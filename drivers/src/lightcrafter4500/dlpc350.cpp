#include "sl/drivers/dlpc350.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace sl::drivers::dlpc350 {

namespace {

std::string hex4(std::uint16_t v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "0x%04X", v);
  return buf;
}

void appendU32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

std::uint32_t u32(const std::vector<std::uint8_t>& d, std::size_t at) {
  return std::uint32_t{d[at]} | std::uint32_t{d[at + 1]} << 8 | std::uint32_t{d[at + 2]} << 16 |
         std::uint32_t{d[at + 3]} << 24;
}

void joinInto(std::string& out, const char* text) {
  if (!out.empty()) out += "; ";
  out += text;
}

}  // namespace

std::string commandName(Command command) {
  switch (command) {
    case Command::kPowerControl:
      return "PowerControl";
    case Command::kGetVersion:
      return "GetVersion";
    case Command::kLedCurrent:
      return "LedCurrent";
    case Command::kLedPwmPolarity:
      return "LedPwmPolarity";
    case Command::kInputSource:
      return "InputSource";
    case Command::kLedEnable:
      return "LedEnable";
    case Command::kHardwareStatus:
      return "HardwareStatus";
    case Command::kSystemStatus:
      return "SystemStatus";
    case Command::kMainStatus:
      return "MainStatus";
    case Command::kValidate:
      return "ValidateLut";
    case Command::kDisplayMode:
      return "DisplayMode";
    case Command::kTriggerOut1:
      return "TriggerOut1";
    case Command::kTriggerOut2:
      return "TriggerOut2";
    case Command::kPatternSource:
      return "PatternSource";
    case Command::kPatternTriggerMode:
      return "PatternTriggerMode";
    case Command::kPatternStartStop:
      return "PatternStartStop";
    case Command::kExposureFramePeriod:
      return "ExposureFramePeriod";
    case Command::kPatternConfig:
      return "PatternConfig";
    case Command::kMailboxOffset:
      return "LutOffset";
    case Command::kMailboxControl:
      return "LutAccessControl";
    case Command::kMailboxData:
      return "LutData";
    case Command::kTriggerIn1Delay:
      return "TriggerIn1Delay";
    case Command::kImagesInFlash:
      return "ImagesInFlash";
  }
  return "Command";
}

Dlpc350Error::Dlpc350Error(Kind kind, Command command, const std::string& detail)
    : std::runtime_error("DLPC350 " + commandName(command) + " (USB " +
                         hex4(static_cast<std::uint16_t>(command)) + "): " + detail),
      kind_(kind),
      command_(command) {}

std::vector<Report> encodeMessage(std::uint8_t flags, std::uint8_t sequence, Command command,
                                  std::span<const std::uint8_t> data) {
  const std::size_t length = 2 + data.size();
  if (length > 0xFFFF) throw std::invalid_argument("DLPC350 message too long");
  std::vector<std::uint8_t> bytes;
  bytes.reserve(kHeaderSize + length);
  const auto code = static_cast<std::uint16_t>(command);
  bytes.insert(bytes.end(),
               {flags, sequence, static_cast<std::uint8_t>(length & 0xFF),
                static_cast<std::uint8_t>(length >> 8), static_cast<std::uint8_t>(code & 0xFF),
                static_cast<std::uint8_t>(code >> 8)});
  bytes.insert(bytes.end(), data.begin(), data.end());
  std::vector<Report> reports;
  for (std::size_t at = 0; at < bytes.size(); at += kReportSize) {
    Report r{};
    std::copy_n(bytes.begin() + static_cast<std::ptrdiff_t>(at),
                std::min(kReportSize, bytes.size() - at), r.begin());
    reports.push_back(r);
  }
  return reports;
}

ReplyHeader decodeReplyHeader(const Report& first) {
  return ReplyHeader{first[0], first[1],
                     static_cast<std::uint16_t>(first[2] | (std::uint16_t{first[3]} << 8))};
}

std::uint32_t encodePatternLutEntry(const PatternLutEntry& e) {
  if (e.bit_depth < 1 || e.bit_depth > 8)
    throw std::invalid_argument("bit depth " + std::to_string(e.bit_depth) + " not in 1..8");
  const int patterns = 24 / e.bit_depth;  // Table 2-66: patterns per 24-bit image
  const bool fill = e.bit_depth == 1 && e.pattern_number == 24;
  if (e.pattern_number < 0 || (e.pattern_number >= patterns && !fill))
    throw std::invalid_argument("pattern number " + std::to_string(e.pattern_number) +
                                " not in 0.." + std::to_string(patterns - 1) + " for bit depth " +
                                std::to_string(e.bit_depth) +
                                (e.bit_depth == 1 ? " (24 = fill pattern)" : ""));
  if (e.leds > 7) throw std::invalid_argument("LED select not in 0..7");
  std::uint32_t w = static_cast<std::uint32_t>(e.trigger) & 0x3;
  w |= static_cast<std::uint32_t>(e.pattern_number & 0x3F) << 2;
  w |= static_cast<std::uint32_t>(e.bit_depth & 0xF) << 8;
  w |= static_cast<std::uint32_t>(e.leds & 0x7) << 12;
  if (e.invert) w |= 1u << 16;
  if (e.insert_black) w |= 1u << 17;
  if (e.buffer_swap) w |= 1u << 18;
  if (e.trigger_out_previous) w |= 1u << 19;
  return w;
}

PatternLutEntry decodePatternLutEntry(std::uint32_t w) {
  PatternLutEntry e;
  e.trigger = static_cast<TriggerType>(w & 0x3);
  e.pattern_number = static_cast<int>((w >> 2) & 0x3F);
  e.bit_depth = static_cast<int>((w >> 8) & 0xF);
  e.leds = static_cast<std::uint8_t>((w >> 12) & 0x7);
  e.invert = (w >> 16) & 1;
  e.insert_black = (w >> 17) & 1;
  e.buffer_swap = (w >> 18) & 1;
  e.trigger_out_previous = (w >> 19) & 1;
  return e;
}

std::string ValidationStatus::errors() const {
  std::string s;
  if (bits & 0x01) joinInto(s, "selected exposure or frame period settings are invalid");
  if (bits & 0x02) joinInto(s, "selected pattern numbers in the LUT are invalid");
  return s;
}

std::string ValidationStatus::warnings() const {
  std::string s;
  if (bits & 0x04) joinInto(s, "continuous trigger out 1 request or overlapping black sectors");
  if (bits & 0x08)
    joinInto(s, "post vector was not inserted prior to an external triggered vector");
  if (bits & 0x10) joinInto(s, "frame period or exposure difference is less than 230 us");
  return s;
}

std::string Version::format(std::uint32_t v) {
  return std::to_string(v >> 24) + "." + std::to_string((v >> 16) & 0xFF) + "." +
         std::to_string(v & 0xFFFF);
}

std::string DeviceStatus::faults() const {
  std::string s;
  // Hardware Status: bit 0 = internal initialisation successful; 1, 2, 3, 6, 7 = errors.
  if (!(hardware & 0x01)) joinInto(s, "internal initialization failed");
  if (hardware & 0x02) joinInto(s, "incompatible controller or DMD");
  if (hardware & 0x04) joinInto(s, "DMD reset waveform controller error");
  if (hardware & 0x08) joinInto(s, "forced swap error");
  if (hardware & 0x40) joinInto(s, "sequencer abort status error");
  if (hardware & 0x80) joinInto(s, "sequencer error");
  // System Status: bit 0 = internal memory test passed.
  if (!(system & 0x01)) joinInto(s, "internal memory test failed");
  return s;
}

std::uint8_t triggerDelayRaw(double delay_us) {
  const double raw = 0xBB + std::round(delay_us / 0.1072);
  if (!(raw >= 0 && raw <= 0xD5))
    throw std::invalid_argument("trigger delay " + std::to_string(delay_us) +
                                " us not in -20.05..+2.787 us");
  return static_cast<std::uint8_t>(raw);
}

// --- Dlpc350 -------------------------------------------------------------------

Dlpc350::Dlpc350(HidTransport& transport, std::chrono::milliseconds reply_timeout, Log log)
    : transport_(transport), reply_timeout_(reply_timeout), log_(std::move(log)) {}

std::vector<std::uint8_t> Dlpc350::transact(Command command, std::uint8_t flags,
                                            std::span<const std::uint8_t> data,
                                            std::size_t min_length) {
  using Kind = Dlpc350Error::Kind;
  const std::uint8_t seq = sequence_++;
  const auto reports =
      encodeMessage(static_cast<std::uint8_t>(flags | kFlagReply), seq, command, data);
  // Reads one whole reply (first report + continuation reports), or nullopt
  // when no first report arrives within `wait`.
  auto readReply = [&](std::chrono::milliseconds wait)
      -> std::optional<std::pair<ReplyHeader, std::vector<std::uint8_t>>> {
    std::optional<Report> first = transport_.read(wait);
    if (!first) return std::nullopt;
    const ReplyHeader h = decodeReplyHeader(*first);
    // Reply payload continues in further reports (guide 1.2).
    std::vector<std::uint8_t> payload(first->begin() + kHeaderSize, first->end());
    while (payload.size() < h.length) {
      std::optional<Report> more = transport_.read(reply_timeout_);
      if (!more)
        throw Dlpc350Error(Kind::kTimeout, command,
                           "reply of " + std::to_string(h.length) + " bytes ended after " +
                               std::to_string(payload.size()));
      payload.insert(payload.end(), more->begin(), more->end());
    }
    payload.resize(h.length);
    return std::make_pair(h, std::move(payload));
  };
  try {
    // Replies still waiting belong to earlier requests that timed out.
    while (readReply(std::chrono::milliseconds(0))) ++stale_;
    for (const Report& r : reports) transport_.write(r);
    const auto deadline = std::chrono::steady_clock::now() + reply_timeout_;
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      auto reply = left.count() > 0 ? readReply(left) : std::nullopt;
      if (!reply)
        throw Dlpc350Error(Kind::kTimeout, command,
                           "no reply within " + std::to_string(reply_timeout_.count()) + " ms");
      const ReplyHeader& h = reply->first;
      if (h.sequence == seq) {
        if (mismatches_ == 0) ++echoed_;
      } else if (echoed_ >= kEchoProof) {
        ++stale_;  // an echoing device: a late reply to an earlier request
        continue;
      } else {
        // The device numbers its replies its own way (TI's API never checks
        // them): this is the reply to the one outstanding request.
        ++mismatches_;
        echoed_ = 0;
        if (!mismatch_logged_ && log_) {
          mismatch_logged_ = true;
          log_("DLPC350 " + commandName(command) + ": reply carries sequence " +
               std::to_string(h.sequence) + " for request " + std::to_string(seq) +
               "; the device does not echo sequence numbers, replies are matched to the one "
               "outstanding request (logged once)");
        }
      }
      if (h.error())
        throw Dlpc350Error(Kind::kNack, command, "the projector rejected the command (NACK)");
      if (reply->second.size() < min_length)
        throw Dlpc350Error(Kind::kProtocol, command,
                           "reply has " + std::to_string(reply->second.size()) +
                               " data bytes, expected " + std::to_string(min_length));
      return std::move(reply->second);
    }
  } catch (const HidError& e) {
    throw Dlpc350Error(Kind::kDevice, command, e.what());
  }
}

void Dlpc350::write(Command command, std::span<const std::uint8_t> data) {
  transact(command, 0, data, 0);
}

std::vector<std::uint8_t> Dlpc350::read(Command command, std::size_t min_length) {
  // A read with zero data bytes is a NACK too (the device always returns data).
  auto payload = transact(command, kFlagRead, {}, std::max<std::size_t>(min_length, 1));
  return payload;
}

void Dlpc350::setPowerStandby(bool standby) {
  const std::uint8_t d[] = {standby ? std::uint8_t{1} : std::uint8_t{0}};
  write(Command::kPowerControl, d);
}
bool Dlpc350::powerStandby() { return (read(Command::kPowerControl, 1)[0] & 0x03) != 0; }

void Dlpc350::setDisplayMode(DisplayMode mode) {
  const std::uint8_t d[] = {static_cast<std::uint8_t>(mode)};
  write(Command::kDisplayMode, d);
}
DisplayMode Dlpc350::displayMode() {
  return read(Command::kDisplayMode, 1)[0] ? DisplayMode::kPattern : DisplayMode::kVideo;
}

void Dlpc350::setPatternSource(PatternSource source) {
  const std::uint8_t d[] = {static_cast<std::uint8_t>(source)};
  write(Command::kPatternSource, d);
}
PatternSource Dlpc350::patternSource() {
  return read(Command::kPatternSource, 1)[0] == 0 ? PatternSource::kVideoPort
                                                  : PatternSource::kFlash;
}

void Dlpc350::setTriggerMode(TriggerMode mode) {
  const std::uint8_t d[] = {static_cast<std::uint8_t>(mode)};
  write(Command::kPatternTriggerMode, d);
}
TriggerMode Dlpc350::triggerMode() {
  return static_cast<TriggerMode>(read(Command::kPatternTriggerMode, 1)[0]);
}

void Dlpc350::setPatternAction(PatternAction action) {
  const std::uint8_t d[] = {static_cast<std::uint8_t>(action)};
  write(Command::kPatternStartStop, d);
}
PatternAction Dlpc350::patternAction() {
  return static_cast<PatternAction>(read(Command::kPatternStartStop, 1)[0] & 0x03);
}

void Dlpc350::setExposureFramePeriod(std::uint32_t exposure_us, std::uint32_t frame_period_us) {
  std::vector<std::uint8_t> d;
  appendU32(d, exposure_us);
  appendU32(d, frame_period_us);
  write(Command::kExposureFramePeriod, d);
}
std::pair<std::uint32_t, std::uint32_t> Dlpc350::exposureFramePeriod() {
  const auto d = read(Command::kExposureFramePeriod, 8);
  return {u32(d, 0), u32(d, 4)};
}

void Dlpc350::setPatternConfig(const PatternConfig& c) {
  if (c.lut_entries < 1 || c.lut_entries > 128)
    throw std::invalid_argument("pattern LUT entries " + std::to_string(c.lut_entries) +
                                " not in 1..128");
  if (c.trigger_out2_patterns < 1 || c.trigger_out2_patterns > 256)
    throw std::invalid_argument("trigger out 2 patterns not in 1..256");
  if (c.image_lut_entries < 1 || c.image_lut_entries > 64)
    throw std::invalid_argument("image LUT entries " + std::to_string(c.image_lut_entries) +
                                " not in 1..64");
  const std::uint8_t d[] = {static_cast<std::uint8_t>(c.lut_entries - 1),
                            static_cast<std::uint8_t>(c.repeat ? 1 : 0),
                            static_cast<std::uint8_t>(c.trigger_out2_patterns - 1),
                            static_cast<std::uint8_t>(c.image_lut_entries - 1)};
  write(Command::kPatternConfig, d);
}
PatternConfig Dlpc350::patternConfig() {
  const auto d = read(Command::kPatternConfig, 4);
  return PatternConfig{d[0] + 1, d[1] != 0, d[2] + 1, d[3] + 1};
}

void Dlpc350::setMailbox(Mailbox mailbox) {
  const std::uint8_t d[] = {static_cast<std::uint8_t>(mailbox)};
  write(Command::kMailboxControl, d);
}

void Dlpc350::setMailboxOffset(std::uint8_t offset) {
  if (offset > 127) throw std::invalid_argument("LUT offset not in 0..127");
  const std::uint8_t d[] = {offset};
  write(Command::kMailboxOffset, d);
}

void Dlpc350::writeMailboxData(std::span<const std::uint8_t> data) {
  write(Command::kMailboxData, data);
}

void Dlpc350::writePatternLut(const std::vector<PatternLutEntry>& entries) {
  if (entries.empty() || entries.size() > 128)
    throw std::invalid_argument("pattern LUT needs 1..128 entries");
  std::vector<std::uint8_t> d;
  for (const auto& e : entries) {
    const std::uint32_t w = encodePatternLutEntry(e);
    d.insert(d.end(), {static_cast<std::uint8_t>(w), static_cast<std::uint8_t>(w >> 8),
                       static_cast<std::uint8_t>(w >> 16)});
  }
  setMailbox(Mailbox::kPatternLut);
  setMailboxOffset(0);
  writeMailboxData(d);
  setMailbox(Mailbox::kClosed);
}

void Dlpc350::writeImageLut(const std::vector<std::uint8_t>& indices) {
  if (indices.empty() || indices.size() > 64)
    throw std::invalid_argument("image LUT needs 1..64 entries");
  std::vector<std::uint8_t> d = indices;
  if (d.size() == 2) std::swap(d[0], d[1]);  // firmware quirk, see the header
  setMailbox(Mailbox::kImageLut);
  setMailboxOffset(0);
  writeMailboxData(d);
  setMailbox(Mailbox::kClosed);
}

void Dlpc350::startValidation() {
  const std::uint8_t d[] = {0};
  write(Command::kValidate, d);
}
ValidationStatus Dlpc350::validationStatus() {
  return ValidationStatus{read(Command::kValidate, 1)[0]};
}

void Dlpc350::setLedCurrents(std::uint8_t red, std::uint8_t green, std::uint8_t blue) {
  const std::uint8_t d[] = {red, green, blue};
  write(Command::kLedCurrent, d);
}
std::array<std::uint8_t, 3> Dlpc350::ledCurrents() {
  const auto d = read(Command::kLedCurrent, 3);
  return {d[0], d[1], d[2]};
}

void Dlpc350::setLedPwmInverted(bool inverted) {
  const std::uint8_t d[] = {static_cast<std::uint8_t>(inverted ? 1 : 0)};
  write(Command::kLedPwmPolarity, d);
}
bool Dlpc350::ledPwmInverted() { return (read(Command::kLedPwmPolarity, 1)[0] & 0x01) != 0; }

void Dlpc350::setLedEnables(bool sequencer_controlled, bool red, bool green, bool blue) {
  const std::uint8_t d[] = {static_cast<std::uint8_t>(
      (red ? 1 : 0) | (green ? 2 : 0) | (blue ? 4 : 0) | (sequencer_controlled ? 8 : 0))};
  write(Command::kLedEnable, d);
}

void Dlpc350::setTriggerOut(int output, bool invert, std::uint8_t rising, std::uint8_t falling) {
  if (output == 1) {
    const std::uint8_t d[] = {static_cast<std::uint8_t>(invert ? 1 : 0), rising, falling};
    write(Command::kTriggerOut1, d);
  } else if (output == 2) {
    const std::uint8_t d[] = {static_cast<std::uint8_t>(invert ? 1 : 0), rising};
    write(Command::kTriggerOut2, d);
  } else {
    throw std::invalid_argument("trigger output must be 1 or 2");
  }
}

void Dlpc350::setTriggerIn1Delay(std::uint32_t steps) {
  std::vector<std::uint8_t> d;
  appendU32(d, steps & 0x7FFFF);
  write(Command::kTriggerIn1Delay, d);
}

Version Dlpc350::version() {
  const auto d = read(Command::kGetVersion, 16);
  return Version{u32(d, 0), u32(d, 4), u32(d, 8), u32(d, 12)};
}

DeviceStatus Dlpc350::status() {
  DeviceStatus s;
  s.hardware = read(Command::kHardwareStatus, 1)[0];
  s.system = read(Command::kSystemStatus, 1)[0];
  s.main = read(Command::kMainStatus, 1)[0];
  return s;
}

int Dlpc350::imagesInFlash() { return read(Command::kImagesInFlash, 1)[0]; }

}  // namespace sl::drivers::dlpc350
