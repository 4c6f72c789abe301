#include <set>
#include <stdexcept>
#include <thread>

#include "sl/drivers/lightcrafter4500.h"

namespace sl::drivers {

namespace dl = dlpc350;

namespace {

// Minimum pattern exposure per bit depth 1..8, microseconds ("Pattern
// Exposure Time and Frame Period": the exposure a bit depth needs).
constexpr std::uint32_t kMinExposureUs[8] = {235, 700, 1570, 1700, 2000, 2500, 4500, 8333};

std::uint8_t ledValue(std::uint8_t v, bool inverted) {
  return inverted ? static_cast<std::uint8_t>(255 - v) : v;
}

}  // namespace

std::vector<LightCrafter4500Sequence> builtinSequences(std::uint32_t period_us) {
  // The 1-bit fill pattern: black, white when inverted (dlpc350::fillPattern
  // gives the source).
  auto fill = [&](bool is_white) {
    const dl::FillPattern f = dl::fillPattern(is_white);
    LightCrafter4500Sequence s;
    s.name = is_white ? "white" : "black";
    s.patterns = {LightCrafter4500Pattern{0, f.pattern_number, f.bit_depth, f.invert}};
    s.exposure_us = s.frame_period_us = period_us;
    return s;
  };
  return {fill(true), fill(false)};
}

void validateSequence(const LightCrafter4500Sequence& s) {
  auto fail = [&](const std::string& what) {
    throw std::invalid_argument("sequence '" + s.name + "': " + what);
  };
  if (s.name.empty()) throw std::invalid_argument("sequence without a name");
  if (s.patterns.empty() || s.patterns.size() > 128) fail("needs 1..128 patterns");
  if (s.leds > 7) fail("LED select must be 0..7");
  if (s.exposure_us == 0) fail("exposure_us must be > 0");
  if (s.exposure_us > s.frame_period_us) fail("exposure_us must not exceed frame_period_us");
  if (s.exposure_us != s.frame_period_us && s.frame_period_us - s.exposure_us <= 230)
    fail("frame_period_us must equal exposure_us or exceed it by more than 230 us");
  for (std::size_t i = 0; i < s.patterns.size(); ++i) {
    const auto& p = s.patterns[i];
    const std::string at = "pattern " + std::to_string(i) + ": ";
    if (p.image_index < 0 || p.image_index > 255) fail(at + "image index not in 0..255");
    try {
      dl::encodePatternLutEntry(dl::PatternLutEntry{dl::TriggerType::kInternal, p.channel,
                                                    p.bit_depth, s.leds, p.invert});
    } catch (const std::invalid_argument& e) {
      fail(at + e.what());
    }
    if (s.exposure_us < kMinExposureUs[p.bit_depth - 1])
      fail(at + "exposure " + std::to_string(s.exposure_us) + " us is below the " +
           std::to_string(kMinExposureUs[p.bit_depth - 1]) + " us a " +
           std::to_string(p.bit_depth) + "-bit pattern needs");
  }
  if (buildUpload(s).image_lut.size() > 64) fail("needs more than 64 image changes");
}

LightCrafter4500Upload buildUpload(const LightCrafter4500Sequence& s) {
  LightCrafter4500Upload u;
  int previous_image = -1;
  for (std::size_t i = 0; i < s.patterns.size(); ++i) {
    const auto& p = s.patterns[i];
    dl::PatternLutEntry e;
    e.trigger = i == 0 ? s.first_trigger : dl::TriggerType::kInternal;
    e.pattern_number = p.channel;
    e.bit_depth = p.bit_depth;
    e.leds = s.leds;
    e.invert = p.invert;
    e.buffer_swap = p.image_index != previous_image;  // first pattern always swaps in its image
    if (e.buffer_swap) u.image_lut.push_back(static_cast<std::uint8_t>(p.image_index));
    previous_image = p.image_index;
    u.pattern_lut.push_back(e);
  }
  u.config.lut_entries = static_cast<int>(u.pattern_lut.size());
  u.config.repeat = true;
  u.config.trigger_out2_patterns = u.config.lut_entries;  // TRIG_OUT_2 once per sequence
  u.config.image_lut_entries = static_cast<int>(u.image_lut.size());
  return u;
}

LightCrafter4500Upload buildSingleUpload(const LightCrafter4500Sequence& s, int index) {
  if (index < 0 || static_cast<std::size_t>(index) >= s.patterns.size())
    throw std::out_of_range("sequence '" + s.name + "': pattern " + std::to_string(index) +
                            " not in 0.." + std::to_string(s.patterns.size() - 1));
  const LightCrafter4500Pattern& p = s.patterns[static_cast<std::size_t>(index)];
  LightCrafter4500Upload u;
  dl::PatternLutEntry e;
  e.trigger = dl::TriggerType::kInternal;  // no trigger input: the timer repeats it
  e.pattern_number = p.channel;
  e.bit_depth = p.bit_depth;
  e.leds = s.leds;
  e.invert = p.invert;
  e.buffer_swap = true;  // load its image
  u.pattern_lut = {e};
  u.image_lut = {static_cast<std::uint8_t>(p.image_index)};
  u.config = dl::PatternConfig{1, true, 1, 1};
  return u;
}

LightCrafter4500Projector::LightCrafter4500Projector(LightCrafter4500Config config,
                                                     TransportFactory open_transport,
                                                     dl::Dlpc350::Log log)
    : config_(std::move(config)), open_transport_(std::move(open_transport)), log_(std::move(log)) {
  std::set<std::string> names;
  for (const auto& s : config_.sequences) all_.push_back(s);
  for (const auto& s : builtinSequences(config_.white_black_period_us)) all_.push_back(s);
  for (const auto& s : all_) {
    validateSequence(s);
    if (!names.insert(s.name).second)
      throw std::invalid_argument("duplicate projector sequence '" + s.name + "'");
  }
  std::lock_guard lock(mutex_);
  withDevice([] {});
}

LightCrafter4500Projector::~LightCrafter4500Projector() {
  try {
    std::lock_guard lock(mutex_);
    if (device_ && running_) device_->setPatternAction(dl::PatternAction::kStop);
  } catch (...) {
  }
}

std::string LightCrafter4500Projector::id() const { return config_.id; }

std::vector<ProjectorSequence> LightCrafter4500Projector::sequences() const {
  std::vector<ProjectorSequence> out;
  for (const auto& s : all_) out.push_back({s.name, static_cast<int>(s.patterns.size())});
  return out;
}

const LightCrafter4500Sequence* LightCrafter4500Projector::find(const std::string& name) const {
  for (const auto& s : all_)
    if (s.name == name) return &s;
  return nullptr;
}

template <typename F>
auto LightCrafter4500Projector::withDevice(F&& f) -> decltype(f()) {
  try {
    if (!device_) connectLocked();
    return f();
  } catch (const dl::Dlpc350Error& e) {
    if (e.kind() == dl::Dlpc350Error::Kind::kDevice) {
      // Unplugged or I/O failure: drop the handle; the next call reopens it.
      device_.reset();
      transport_.reset();
      uploaded_.clear();
      running_ = false;
      held_ = -1;
    }
    throw;
  }
}

void LightCrafter4500Projector::connectLocked() {
  transport_ = open_transport_();
  device_ = std::make_unique<dl::Dlpc350>(*transport_, config_.reply_timeout, log_);
  uploaded_.clear();
  version_ = dl::Version::format(device_->version().application);
  const auto deadline = std::chrono::steady_clock::now() + config_.power_up_timeout;
  if (device_->powerStandby()) {
    device_->setPowerStandby(false);
    while (device_->powerStandby()) {
      if (std::chrono::steady_clock::now() > deadline)
        throw std::runtime_error(config_.id + ": still in standby after " +
                                 std::to_string(config_.power_up_timeout.count()) + " ms");
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  const dl::DeviceStatus status = device_->status();
  if (!status.faults().empty())
    throw std::runtime_error(config_.id + ": the projector reports: " + status.faults());
  if (device_->displayMode() != dl::DisplayMode::kPattern) {
    device_->setDisplayMode(dl::DisplayMode::kPattern);
    while (device_->displayMode() != dl::DisplayMode::kPattern) {
      if (std::chrono::steady_clock::now() > deadline)
        throw std::runtime_error(config_.id + ": did not switch to pattern mode");
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
  device_->setPatternAction(dl::PatternAction::kStop);
  running_ = false;
  // LED PWM polarity explicitly (not the power-on default), read back.
  device_->setLedPwmInverted(config_.led_pwm_polarity_inverted);
  if (device_->ledPwmInverted() != config_.led_pwm_polarity_inverted)
    throw std::runtime_error(
        config_.id + ": LED PWM polarity (DLPC350 " +
        dl::commandName(dl::Command::kLedPwmPolarity) + ", USB 0x1A05) reads back " +
        (config_.led_pwm_polarity_inverted ? "normal" : "inverted") + " after setting it " +
        (config_.led_pwm_polarity_inverted ? "inverted" : "normal"));
  const bool inv = config_.led_pwm_inverted;
  device_->setLedCurrents(ledValue(config_.led_current_red, inv),
                          ledValue(config_.led_current_green, inv),
                          ledValue(config_.led_current_blue, inv));
  device_->setLedEnables(true, false, false, false);  // the sequencer switches the LEDs
  device_->setTriggerOut(1, config_.trigger_out1_invert,
                         dl::triggerDelayRaw(config_.trigger_out1_rising_delay_us),
                         dl::triggerDelayRaw(config_.trigger_out1_falling_delay_us));
}

void LightCrafter4500Projector::uploadLocked(const LightCrafter4500Sequence& s) {
  sendUploadLocked(s, buildUpload(s), "sequence '" + s.name + "'");
  uploaded_ = s.name;
}

void LightCrafter4500Projector::sendUploadLocked(const LightCrafter4500Sequence& s,
                                                 const LightCrafter4500Upload& u,
                                                 const std::string& what) {
  const int images = device_->imagesInFlash();
  for (const std::uint8_t image : u.image_lut)
    if (image >= images)
      throw std::runtime_error(config_.id + ": " + what + " uses flash image " +
                               std::to_string(image) + " but the projector's flash holds " +
                               std::to_string(images) + " images");
  uploaded_.clear();
  held_ = -1;
  device_->setPatternAction(dl::PatternAction::kStop);
  device_->setPatternSource(dl::PatternSource::kFlash);
  device_->setTriggerMode(dl::TriggerMode::kInternalOrExternal);
  device_->setExposureFramePeriod(s.exposure_us, s.frame_period_us);
  device_->setPatternConfig(u.config);
  device_->writePatternLut(u.pattern_lut);
  device_->writeImageLut(u.image_lut);
  device_->startValidation();
  const std::string validate =
      "(DLPC350 " + dl::commandName(dl::Command::kValidate) + ", USB 0x1A1A)";
  const auto deadline = std::chrono::steady_clock::now() + config_.validation_timeout;
  dl::ValidationStatus status = device_->validationStatus();
  while (status.busy()) {
    if (std::chrono::steady_clock::now() > deadline)
      throw std::runtime_error(config_.id + ": validation of " + what + " " + validate +
                               " did not finish within " +
                               std::to_string(config_.validation_timeout.count()) + " ms");
    std::this_thread::sleep_for(config_.validation_poll);
    status = device_->validationStatus();
  }
  if (!status.valid())
    throw std::runtime_error(config_.id + ": " + what + " refused by the projector " + validate +
                             ": " + status.errors());
  warnings_ = status.warnings();
}

void LightCrafter4500Projector::select(const std::string& name) {
  const LightCrafter4500Sequence* s = find(name);
  if (!s) throw std::invalid_argument(config_.id + ": unknown sequence '" + name + "'");
  std::lock_guard lock(mutex_);
  if (running_) throw std::logic_error(config_.id + ": cannot select a sequence while running");
  selected_ = name;
  withDevice([&] {
    if (uploaded_ != name) uploadLocked(*s);
  });
}

void LightCrafter4500Projector::start(int /*count*/) {
  std::lock_guard lock(mutex_);
  if (selected_.empty()) throw std::logic_error(config_.id + ": no sequence selected");
  withDevice([&] {
    if (uploaded_ != selected_) uploadLocked(*find(selected_));  // also after projectSingle()
    device_->setPatternAction(dl::PatternAction::kStart);
    held_ = -1;
    running_ = true;
  });
}

void LightCrafter4500Projector::stop() {
  std::lock_guard lock(mutex_);
  running_ = false;
  held_ = -1;
  withDevice([&] { device_->setPatternAction(dl::PatternAction::kStop); });
}

void LightCrafter4500Projector::projectSingle(int index) {
  std::lock_guard lock(mutex_);
  const std::string call = config_.id + ": projectSingle(" + std::to_string(index) + ")";
  if (running_) throw std::logic_error(call + ": a sequence is running; stop() first");
  if (selected_.empty()) throw std::logic_error(call + ": no sequence selected");
  const LightCrafter4500Sequence& s = *find(selected_);
  if (index < 0 || static_cast<std::size_t>(index) >= s.patterns.size())
    throw std::out_of_range(call + ": sequence '" + s.name + "' has patterns 0.." +
                            std::to_string(s.patterns.size() - 1));
  if (held_ == index) return;  // already shown
  const std::string what = "pattern " + std::to_string(index) + " of sequence '" + s.name + "'";
  try {
    withDevice([&] {
      sendUploadLocked(s, buildSingleUpload(s, index), what);
      device_->setPatternAction(dl::PatternAction::kStart);
      held_ = index;
    });
  } catch (const dl::Dlpc350Error& e) {  // names the command
    throw std::runtime_error(config_.id + ": showing " + what + ": " + e.what());
  } catch (const dl::HidError& e) {  // reopening failed
    throw std::runtime_error(config_.id + ": showing " + what + ": " + e.what());
  }
}

std::string LightCrafter4500Projector::firmwareVersion() const {
  std::lock_guard lock(mutex_);
  return version_;
}

std::string LightCrafter4500Projector::lastValidationWarnings() const {
  std::lock_guard lock(mutex_);
  return warnings_;
}

}  // namespace sl::drivers
