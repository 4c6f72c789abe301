// TI DLPC350 (the controller of the DLP LightCrafter 4500) over USB HID: the
// transport interface and the command layer.
//
// Every command code, field layout and bit below comes from the DLPC350
// Programmer's Guide (TI DLPU010), cited by the command's title and USB code
// as the guide lists them ("Pattern Display LUT Control, USB 0x1A31"); the
// protocol framing is the guide's section 1.2 "USB Interface".
//
// Framing (guide 1.2, "USB transaction sequence"): each HID report is 64 bytes
// (hidapi adds a leading report id 0 on writes). The first report of a
// message holds a 4-byte header and the start of the payload:
//   byte 0  flags: bit 7 = 1 read / 0 write, bit 6 = reply requested,
//           bit 5 = error (set by the device in a reply: command not found or
//           failed, i.e. NACK), bits 2:0 = destination (0 = projector control)
//   byte 1  sequence number. Whether the device echoes it is not certain:
//           TI's host API (v4.0.0, dlpc350_api.cpp) increments it on writes
//           only, sends 0 on reads and never checks the reply's. Replies are
//           therefore matched to the one outstanding request (see Dlpc350).
//   byte 2-3 payload length, little endian (command code + data bytes)
//   byte 4.. payload: 2-byte command code, little endian (0x1A1B goes out as
//           1B 1A), then the command's data
// A payload longer than the 60 bytes that fit in the first report continues
// in further 64-byte reports that carry payload bytes only (no header).
// Replies are framed the same way; their payload is the data only.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace sl::drivers::dlpc350 {

inline constexpr std::size_t kReportSize = 64;    // bytes per HID report (no report id)
inline constexpr std::size_t kHeaderSize = 4;     // flags, sequence, length (2)
inline constexpr std::uint8_t kFlagRead = 0x80;   // guide 1.2: bit 7
inline constexpr std::uint8_t kFlagReply = 0x40;  // guide 1.2: bit 6
inline constexpr std::uint8_t kFlagError = 0x20;  // guide 1.2: bit 5 (device reply)

using Report = std::array<std::uint8_t, kReportSize>;

// A failure of the USB HID link itself (device missing, unplugged, I/O error).
class HidError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One HID device. Implementations: the hidapi one (openHidapiTransport) and
// the tests' fake. Thread-compatible: the command layer serialises access.
class HidTransport {
 public:
  virtual ~HidTransport() = default;
  // Sends one 64-byte output report. Throws HidError on failure.
  virtual void write(const Report& report) = 0;
  // Next 64-byte input report, or nullopt when none arrives within `timeout`.
  // Throws HidError on failure.
  virtual std::optional<Report> read(std::chrono::milliseconds timeout) = 0;
};

// USB command codes (CMD2 << 8 | CMD3), as the guide's command tables list them.
enum class Command : std::uint16_t {
  kPowerControl = 0x0200,         // "Power Control"
  kGetVersion = 0x0205,           // "Retrieve Firmware Version" (read only)
  kLedCurrent = 0x0B01,           // "LED Driver Current Control"
  kLedPwmPolarity = 0x1A05,       // "LED PWM Polarity" (TI API: PWM_INVERT, 1 byte)
  kInputSource = 0x1A00,          // "Input Source Selection" (not used in pattern mode)
  kLedEnable = 0x1A07,            // "LED Enable Outputs"
  kHardwareStatus = 0x1A0A,       // "Hardware Status" (read only)
  kSystemStatus = 0x1A0B,         // "System Status" (read only)
  kMainStatus = 0x1A0C,           // "Main Status" (read only)
  kValidate = 0x1A1A,             // "Validate Data Command Response"
  kDisplayMode = 0x1A1B,          // "Display Mode Selection"
  kTriggerOut1 = 0x1A1D,          // "Trigger Out1 Control"
  kTriggerOut2 = 0x1A1E,          // "Trigger Out2 Control"
  kPatternSource = 0x1A22,        // "Pattern Display Data Input Source"
  kPatternTriggerMode = 0x1A23,   // "Pattern Trigger Mode Selection"
  kPatternStartStop = 0x1A24,     // "Pattern Display Start/Stop Pattern Sequence"
  kExposureFramePeriod = 0x1A29,  // "Pattern Exposure Time and Frame Period"
  kPatternConfig = 0x1A31,        // "Pattern Display LUT Control"
  kMailboxOffset = 0x1A32,        // "Pattern Display LUT Offset Pointer"
  kMailboxControl = 0x1A33,       // "Pattern Display LUT Access Control"
  kMailboxData = 0x1A34,          // "Pattern Display LUT Data"
  kTriggerIn1Delay = 0x1A35,      // "Trigger In1 Control" (delay)
  kImagesInFlash = 0x1A42,        // "Number of Images in Flash" (read only)
};
// Guide title of a command, for error messages ("PatternConfig (USB 0x1A31)").
std::string commandName(Command command);

// Error of one command: the message names the command and its USB code.
class Dlpc350Error : public std::runtime_error {
 public:
  enum class Kind {
    kTimeout,   // no reply within the reply timeout
    kNack,      // the device set the error flag (command not found or failed)
    kDevice,    // HID I/O failed: device missing or unplugged
    kProtocol,  // malformed reply (too short, wrong length)
  };
  Dlpc350Error(Kind kind, Command command, const std::string& detail);
  Kind kind() const { return kind_; }
  Command command() const { return command_; }

 private:
  Kind kind_;
  Command command_;
};

// --- framing -----------------------------------------------------------------

// The reports of one message (guide 1.2): header + payload split over
// 64-byte reports, unused bytes zero.
std::vector<Report> encodeMessage(std::uint8_t flags, std::uint8_t sequence, Command command,
                                  std::span<const std::uint8_t> data);

struct ReplyHeader {
  std::uint8_t flags = 0;
  std::uint8_t sequence = 0;
  std::uint16_t length = 0;  // data bytes that follow
  bool error() const { return (flags & kFlagError) != 0; }
};
ReplyHeader decodeReplyHeader(const Report& first);

// --- field types -------------------------------------------------------------

enum class DisplayMode : std::uint8_t { kVideo = 0, kPattern = 1 };  // Display Mode Selection
// Pattern Display Data Input Source: 0 = video port (RGB/FPD-link), 3 = flash.
enum class PatternSource : std::uint8_t { kVideoPort = 0, kFlash = 3 };
// Pattern Trigger Mode Selection: 0 = VSYNC, 1 = internal or external
// (TRIG_IN_1/2) trigger; 2..4 (TRIG_IN pairs, variable exposure) are unused here.
enum class TriggerMode : std::uint8_t { kVsync = 0, kInternalOrExternal = 1 };
// Pattern Display Start/Stop: 0 stop (restart from the beginning), 1 pause, 2 start.
enum class PatternAction : std::uint8_t { kStop = 0, kPause = 1, kStart = 2 };
// Pattern Display LUT Access Control: 0 closes, 1 opens the image index LUT,
// 2 opens the pattern definition LUT.
enum class Mailbox : std::uint8_t { kClosed = 0, kImageLut = 1, kPatternLut = 2 };
// Trigger type of a pattern LUT entry (guide Table 2-65, bits 1:0).
enum class TriggerType : std::uint8_t {
  kInternal = 0,          // advance on the internal frame-period timer
  kExternalPositive = 1,  // wait for a rising TRIG_IN_1 edge
  kExternalNegative = 2,  // wait for a falling TRIG_IN_1 edge
  kNone = 3,              // continue from the previous pattern
};
// The 1-bit fill pattern and its polarity. The Programmer's Guide's pattern
// number mapping (DLPU010, "Pattern Number Mapping" with Table 2-65/2-66)
// maps the 1-bit numbers 0..23 to the bit planes G0..G7, R0..R7, B0..B7 of
// the flash image; 24 is no bit plane of the image but the fill that the
// sequencer also uses for "insert black" (bit 17: a black-fill pattern after
// the entry), and "invert pattern" (bit 16) complements whatever the entry
// shows. So 24 is black and 24 inverted is white. TI's API v4.0.0 comment of
// DLPC350_AddToPatLut says "25 = white, inverted = black", but its own code
// rejects numbers above 24, and the SL sensor's vendored copy (ethz-asl/
// sl_sensor, lc4500api) corrected the comment to "24 -> black; inverted ->
// white" after running it on the device; its colour sequence shows white as
// 24 inverted. Every white/black frame of this driver (the built-in "white"
// and "black" sequences, Gray-code reference frames written as "white" /
// "black" channels in the hardware config) goes through fillPattern().
inline constexpr int kFillPattern = 24;
struct FillPattern {
  int pattern_number = kFillPattern;
  int bit_depth = 1;
  bool invert = false;
};
inline constexpr FillPattern fillPattern(bool white) { return {kFillPattern, 1, white}; }

// LED select of a pattern LUT entry (Table 2-65, bits 14:12): bit 0 red,
// bit 1 green, bit 2 blue; 7 = white, 0 = none (pass through).
inline constexpr std::uint8_t kLedRed = 1, kLedGreen = 2, kLedBlue = 4, kLedWhite = 7;

// One pattern LUT entry (guide Table 2-65, 24 bits sent as 3 bytes LSB first):
//   bits 1:0   trigger type
//   bits 7:2   pattern number: which bit planes of the 24-bit flash image are
//              shown (Table 2-66): for bit depth d, 0 .. floor(24 / d) - 1,
//              e.g. 0..2 = G, R, B planes of an 8-bit image; for d = 1 the
//              number 24 is the fill pattern: BLACK, white when inverted
//              (kFillPattern below says why)
//   bits 11:8  bit depth 1..8
//   bits 14:12 LED select
//   bit 16     invert pattern
//   bit 17     insert black-fill pattern after this one
//   bit 18     buffer swap (show the next image of the image LUT)
//   bit 19     trigger out 1 continues from the previous pattern
struct PatternLutEntry {
  TriggerType trigger = TriggerType::kInternal;
  int pattern_number = 0;
  int bit_depth = 8;
  std::uint8_t leds = kLedWhite;
  bool invert = false;
  bool insert_black = false;
  bool buffer_swap = false;
  bool trigger_out_previous = false;
  bool operator==(const PatternLutEntry&) const = default;
};
// Throws std::invalid_argument for a field out of range.
std::uint32_t encodePatternLutEntry(const PatternLutEntry& entry);
PatternLutEntry decodePatternLutEntry(std::uint32_t word);

// Pattern Display LUT Control (0x1A31); the device stores counts minus one.
struct PatternConfig {
  int lut_entries = 1;            // 1..128 pattern LUT entries
  bool repeat = true;             // repeat the sequence until stopped
  int trigger_out2_patterns = 1;  // 1..256: TRIG_OUT_2 every this many patterns
  int image_lut_entries = 1;      // 1..64 image LUT entries (flash source only)
  bool operator==(const PatternConfig&) const = default;
};

// Validate Data Command Response (0x1A1A, read): bit 7 = validation busy.
struct ValidationStatus {
  std::uint8_t bits = 0;
  bool busy() const { return (bits & 0x80) != 0; }
  // Bits 0 and 1 make the sequence invalid; bits 2..4 are warnings.
  bool valid() const { return (bits & 0x03) == 0; }
  std::string errors() const;    // text of bits 0-1, "; "-separated, empty if none
  std::string warnings() const;  // text of bits 2-4
};

struct Version {  // Retrieve Firmware Version: 4 x uint32 little endian
  std::uint32_t application = 0, api = 0, software_config = 0, sequence_config = 0;
  // "major.minor.patch" from bits 31:24, 23:16, 15:0.
  static std::string format(std::uint32_t v);
};

// Hardware Status (0x1A0A), System Status (0x1A0B), Main Status (0x1A0C).
struct DeviceStatus {
  std::uint8_t hardware = 0, system = 0, main = 0;
  // Faults as text ("DMD reset waveform controller error; ..."), empty if none.
  std::string faults() const;
  bool sequencerRunning() const { return (main & 0x02) != 0; }
};

// --- command layer -----------------------------------------------------------

// One method per command. Every write requests a reply and checks it for the
// error flag, as the guide recommends. Errors throw Dlpc350Error naming the
// command. Thread-compatible: callers serialise (LightCrafter4500Projector
// holds a mutex).
//
// Reply matching: only one request is ever outstanding. Before a request,
// replies already waiting (to an earlier request that timed out) are read
// and dropped (staleReplies()); the first reply after the request is its
// reply, whatever its sequence byte. A device that echoes the sequence and a
// device that answers like TI's API expects (its own numbering, 0 on reads)
// both work; the first mismatch is logged once through `log`
// (sequenceMismatches() counts all). Once the device has echoed every
// sequence so far (at least kEchoProof replies), a mismatching reply is taken
// as a late stale one and skipped instead.
class Dlpc350 {
 public:
  using Log = std::function<void(const std::string&)>;
  static constexpr int kEchoProof = 4;
  // `transport` must outlive this object.
  Dlpc350(HidTransport& transport, std::chrono::milliseconds reply_timeout, Log log = {});

  void setPowerStandby(bool standby);  // Power Control: 1 standby, 0 normal
  bool powerStandby();                 // bits 1:0 non-zero = standby
  void setDisplayMode(DisplayMode mode);
  DisplayMode displayMode();
  void setPatternSource(PatternSource source);
  PatternSource patternSource();
  void setTriggerMode(TriggerMode mode);
  TriggerMode triggerMode();
  void setPatternAction(PatternAction action);
  PatternAction patternAction();
  // Pattern Exposure Time and Frame Period, both uint32 microseconds.
  void setExposureFramePeriod(std::uint32_t exposure_us, std::uint32_t frame_period_us);
  std::pair<std::uint32_t, std::uint32_t> exposureFramePeriod();
  void setPatternConfig(const PatternConfig& config);
  PatternConfig patternConfig();
  void setMailbox(Mailbox mailbox);
  void setMailboxOffset(std::uint8_t offset);  // entry offset in the open LUT, 0..127
  void writeMailboxData(std::span<const std::uint8_t> data);
  // Open the pattern LUT mailbox, offset 0, write 3 bytes per entry, close.
  void writePatternLut(const std::vector<PatternLutEntry>& entries);
  // Open the image LUT mailbox, offset 0, write one flash image index per
  // entry, close. With exactly two entries the DLPC350 firmware expects them
  // in reverse order (as TI's reference host code sends them); this does that.
  void writeImageLut(const std::vector<std::uint8_t>& image_indices);
  void startValidation();               // write 0x1A1A
  ValidationStatus validationStatus();  // read 0x1A1A
  // LED Driver Current Control: PWM values 0..255 for red, green, blue.
  void setLedCurrents(std::uint8_t red, std::uint8_t green, std::uint8_t blue);
  std::array<std::uint8_t, 3> ledCurrents();
  // LED PWM Polarity (0x1A05): false = normal (PWM value 0 = LED off), true =
  // inverted. TI's GUI and SLStudio set it to normal at connect.
  void setLedPwmInverted(bool inverted);
  bool ledPwmInverted();
  // LED Enable Outputs: bit 3 = sequencer controls the LEDs, bits 0..2 = R, G, B.
  void setLedEnables(bool sequencer_controlled, bool red, bool green, bool blue);
  // Trigger Out1/Out2 Control: polarity and edge delays in 107.2 ns steps,
  // raw 0xBB = 0 us (see triggerDelayRaw). Out2 has no falling delay.
  void setTriggerOut(int output, bool invert, std::uint8_t rising, std::uint8_t falling);
  // Trigger In1 Control: delay in 107.2 ns steps, bits 18:0.
  void setTriggerIn1Delay(std::uint32_t steps);
  Version version();
  DeviceStatus status();
  int imagesInFlash();

  // Raw access, used by the methods above.
  void write(Command command, std::span<const std::uint8_t> data);
  std::vector<std::uint8_t> read(Command command, std::size_t min_length);

 private:
  std::vector<std::uint8_t> transact(Command command, std::uint8_t flags,
                                     std::span<const std::uint8_t> data, std::size_t min_length);

  HidTransport& transport_;
  std::chrono::milliseconds reply_timeout_;
  Log log_;
  std::uint8_t sequence_ = 0;
  int echoed_ = 0;  // replies whose sequence matched, while none mismatched
  bool mismatch_logged_ = false;
  std::uint64_t mismatches_ = 0, stale_ = 0;

 public:
  std::uint64_t sequenceMismatches() const { return mismatches_; }
  std::uint64_t staleReplies() const { return stale_; }
};

// Trigger output edge delay (Trigger Out1/Out2 Control): raw = 0xBB + round(us
// / 0.1072), valid 0x00 (-20.05 us) .. 0xD5 (+2.787 us). Throws
// std::invalid_argument outside that range.
std::uint8_t triggerDelayRaw(double delay_us);

}  // namespace sl::drivers::dlpc350
