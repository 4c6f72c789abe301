// The TI DLP LightCrafter 4500 as an sl::drivers::Projector: pattern
// sequences stored in the projector's flash (pattern mode, paper section 3.3),
// uploaded as pattern / image LUTs over USB HID (DLPC350 command layer in
// dlpc350.h) and validated by the projector before they run.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "sl/drivers/dlpc350.h"
#include "sl/drivers/projector.h"

namespace sl::drivers {

// One pattern of a sequence: which bit planes of which flash image.
struct LightCrafter4500Pattern {
  int image_index = 0;  // flash image index (image LUT entry), 0..255
  int channel = 0;      // pattern number within the image (Table 2-66), e.g. 0..2 for 8 bits
  int bit_depth = 8;    // 1..8
  bool invert = false;
};

// A named sequence, as in sl_sensor's projector YAML (image indices, channel
// numbers, bit depths, invert flags, exposure, LED colour).
struct LightCrafter4500Sequence {
  std::string name;                               // the daemon's pattern name
  std::vector<LightCrafter4500Pattern> patterns;  // 1..128
  std::uint8_t leds = dlpc350::kLedWhite;         // LED select bits: 1 red, 2 green, 4 blue
  std::uint32_t exposure_us = 16667;              // per pattern, microseconds
  std::uint32_t frame_period_us = 16667;          // per pattern, microseconds (>= exposure)
  // Trigger of the first pattern: external (rising TRIG_IN_1, e.g. from the
  // VersaVIS) or internal (free running); later patterns follow the internal timer.
  dlpc350::TriggerType first_trigger = dlpc350::TriggerType::kInternal;
};

struct LightCrafter4500Config {
  std::string id = "lightcrafter4500";
  std::uint16_t vendor_id = 0x0451;   // TI
  std::uint16_t product_id = 0x6401;  // DLPC350 USB HID
  std::string serial;                 // USB serial number; empty = the first device found
  // LED currents as in TI's LightCrafter 4500 GUI (0..255). The EVM's LED
  // driver takes an inverted PWM, so with led_pwm_inverted the register gets
  // 255 - value (what the GUI and sl_sensor write).
  std::uint8_t led_current_red = 0, led_current_green = 60, led_current_blue = 0;
  bool led_pwm_inverted = true;
  // LED PWM Polarity register (0x1A05), set and read back at every connect
  // instead of trusting the power-on default: false = normal, as TI's GUI and
  // SLStudio set it (they too write 255 - value into the current register).
  bool led_pwm_polarity_inverted = false;
  // TRIG_OUT_1 (drives the cameras when the projector paces them).
  bool trigger_out1_invert = false;
  double trigger_out1_rising_delay_us = 0;   // -20.05 .. +2.787 us
  double trigger_out1_falling_delay_us = 0;  // -20.05 .. +2.787 us
  std::chrono::milliseconds reply_timeout{1000};
  std::chrono::milliseconds validation_timeout{5000};
  std::chrono::milliseconds validation_poll{20};
  std::chrono::milliseconds power_up_timeout{10000};  // leaving standby takes ~5 s
  // Sequences selectable by name, besides the built-in "white" and "black"
  // (1-bit fill pattern 24: black, inverted white, see dlpc350::fillPattern)
  // which use white_black_period_us.
  std::vector<LightCrafter4500Sequence> sequences;
  std::uint32_t white_black_period_us = 16667;
};

// Checks a sequence without a device (counts, ranges, exposure vs period);
// throws std::invalid_argument naming the sequence.
void validateSequence(const LightCrafter4500Sequence& sequence);
// The pattern LUT, image LUT and LUT control of a sequence: buffer swap on
// every change of image, one image LUT entry per swap.
struct LightCrafter4500Upload {
  std::vector<dlpc350::PatternLutEntry> pattern_lut;
  std::vector<std::uint8_t> image_lut;
  dlpc350::PatternConfig config;
};
LightCrafter4500Upload buildUpload(const LightCrafter4500Sequence& sequence);
// The upload that holds pattern `index` of a sequence (software triggering):
// one pattern LUT entry for that image and bit plane, internal trigger, buffer
// swap (its image is loaded), repeated until stopped; one image LUT entry.
// Throws std::out_of_range for an index outside the sequence.
LightCrafter4500Upload buildSingleUpload(const LightCrafter4500Sequence& sequence, int index);

// Opens the device with hidapi (hidraw backend); throws dlpc350::HidError
// ("LightCrafter 4500 (USB 0451:6401) not found") when it is missing.
std::unique_ptr<dlpc350::HidTransport> openHidapiTransport(std::uint16_t vendor_id,
                                                           std::uint16_t product_id,
                                                           const std::string& serial);

// Thread-safe: every method takes an internal mutex (the daemon calls
// select/start/stop from its control thread and on shutdown).
//
// Device faults throw: dlpc350::Dlpc350Error (timeout, NACK, I/O, naming the
// command) or std::runtime_error. After an I/O fault (unplugged) the next call
// reopens the device through the factory and uploads the selected sequence again.
class LightCrafter4500Projector : public Projector {
 public:
  using TransportFactory = std::function<std::unique_ptr<dlpc350::HidTransport>()>;

  // Opens the device, leaves standby, sets the LED PWM polarity, LED
  // currents and trigger outputs. Throws if the device is missing or does not
  // answer. `log` receives notes worth a warning (e.g. a device that does not
  // echo sequence numbers), once each.
  LightCrafter4500Projector(LightCrafter4500Config config, TransportFactory open_transport,
                            dlpc350::Dlpc350::Log log = {});
  ~LightCrafter4500Projector() override;  // stops the sequence (errors ignored)

  std::string id() const override;
  std::vector<ProjectorSequence> sequences() const override;
  // Uploads and validates the sequence (skipped if it is already on the
  // device). Throws std::invalid_argument for an unknown name,
  // std::logic_error while running, std::runtime_error with the projector's
  // reason when validation fails.
  void select(const std::string& name) override;
  void start(int count) override;  // count is not enforced by the device: the engine stops it
  void stop() override;            // also ends a held pattern

  // Software triggering: stops the sequencer, uploads and validates the
  // one-entry LUT of buildSingleUpload (the selected sequence's exposure and
  // period) and starts it, so the projector shows pattern `index` until the
  // next call or stop(). Holding the same pattern again sends nothing. The
  // next start() uploads the full sequence again. Throws std::logic_error
  // while running or without a selected sequence, std::out_of_range for a bad
  // index, std::runtime_error naming the projector, the pattern and the
  // DLPC350 command on a device fault or a refused LUT.
  bool canProjectSingle() const override { return true; }
  void projectSingle(int index) override;

  std::string firmwareVersion() const;         // "major.minor.patch" read at open
  std::string lastValidationWarnings() const;  // warnings of the last validation, if any

 private:
  void connectLocked();
  void uploadLocked(const LightCrafter4500Sequence& sequence);
  // Stop, LUTs and validation; `what` names the upload in errors.
  void sendUploadLocked(const LightCrafter4500Sequence& sequence,
                        const LightCrafter4500Upload& upload, const std::string& what);
  template <typename F>
  auto withDevice(F&& f) -> decltype(f());
  const LightCrafter4500Sequence* find(const std::string& name) const;

  const LightCrafter4500Config config_;
  const TransportFactory open_transport_;
  const dlpc350::Dlpc350::Log log_;
  std::vector<LightCrafter4500Sequence> all_;  // config sequences + white + black
  mutable std::mutex mutex_;
  std::unique_ptr<dlpc350::HidTransport> transport_;  // guarded by mutex_; null = reconnect
  std::unique_ptr<dlpc350::Dlpc350> device_;          // guarded by mutex_
  std::string selected_;                              // guarded by mutex_
  std::string uploaded_;  // guarded by mutex_: sequence on the device, "" = unknown
  bool running_ = false;  // guarded by mutex_
  int held_ = -1;         // guarded by mutex_: pattern shown by projectSingle(), -1 = none
  std::string version_;   // guarded by mutex_
  std::string warnings_;  // guarded by mutex_
};

// The built-in sequences "white" and "black".
std::vector<LightCrafter4500Sequence> builtinSequences(std::uint32_t period_us);

}  // namespace sl::drivers
