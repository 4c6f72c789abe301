// A fake DLPC350 behind dlpc350::HidTransport: records every report written,
// reassembles multi-report messages, keeps the registers a real device
// would, and answers like the device (guide section 1.2 framing). Faults can
// be injected: NACK a command, drop replies (timeout), fail I/O (unplug),
// keep validation busy for a number of polls, report validation bits.
// Sequence numbers in replies: kEcho returns the request's; kTiApi numbers
// them the way TI's host API does its requests (its own counter, incremented
// on writes only, 0 on reads), i.e. never the host's number in general.
#pragma once

#include <map>
#include <optional>
#include <set>
#include <vector>

#include "sl/drivers/dlpc350.h"

namespace sl::test {

namespace dl = drivers::dlpc350;

enum class FakeSequenceStyle { kEcho, kTiApi };

struct FakeDlpc350State {
  FakeSequenceStyle sequence_style = FakeSequenceStyle::kEcho;
  std::uint8_t device_sequence = 0;  // kTiApi: the device's own write counter
  std::uint8_t led_pwm_default = 1;  // 0x1A05 before any write (not what the driver wants)
  bool led_pwm_stuck = false;        // 0x1A05 writes are acknowledged but not kept
  // Delivered just before the next reply (a late reply to an earlier request).
  std::optional<dl::Report> late;
  std::vector<dl::Report> written;                               // every report, in order
  std::map<std::uint16_t, std::vector<std::uint8_t>> registers;  // last write per command
  std::vector<std::vector<std::uint8_t>> mailbox_writes;         // LutData payloads
  std::set<std::uint16_t> nack;      // commands answered with the error flag
  std::set<std::uint16_t> silent;    // commands never answered
  bool unplugged = false;            // every write / read throws HidError
  int validation_busy_polls = 0;     // validation reads with bit 7 set before done
  std::uint8_t validation_bits = 0;  // result bits after validation
  int standby_polls = 0;             // power reads that still say standby
  int images_in_flash = 16;
  std::uint8_t hardware_status = 0x01, system_status = 0x01, main_status = 0x00;
  int opens = 0;
};

class FakeDlpc350 : public dl::HidTransport {
 public:
  explicit FakeDlpc350(FakeDlpc350State& s) : s_(s) { ++s_.opens; }

  void write(const dl::Report& r) override {
    if (s_.unplugged) throw dl::HidError("fake: device unplugged");
    s_.written.push_back(r);
    if (pending_.empty()) {
      expected_ = 4 + (r[2] | (r[3] << 8));
    }
    pending_.insert(pending_.end(), r.begin(), r.end());
    if (pending_.size() < expected_) return;
    pending_.resize(expected_);
    handle(pending_);
    pending_.clear();
  }

  std::optional<dl::Report> read(std::chrono::milliseconds) override {
    if (s_.unplugged) throw dl::HidError("fake: device unplugged");
    if (replies_.empty()) return std::nullopt;
    dl::Report r = replies_.front();
    replies_.erase(replies_.begin());
    return r;
  }

  // Queue an unsolicited (stale) reply, e.g. to an earlier timed-out command.
  void queueRaw(const dl::Report& r) { replies_.push_back(r); }

 private:
  void reply(std::uint8_t flags, std::uint8_t seq, const std::vector<std::uint8_t>& data) {
    if (s_.sequence_style == FakeSequenceStyle::kTiApi)
      seq = (flags & dl::kFlagRead) ? 0 : s_.device_sequence++;
    if (s_.late) {
      replies_.push_back(*s_.late);
      s_.late.reset();
    }
    std::vector<std::uint8_t> bytes{flags, seq, static_cast<std::uint8_t>(data.size()),
                                    static_cast<std::uint8_t>(data.size() >> 8)};
    bytes.insert(bytes.end(), data.begin(), data.end());
    for (std::size_t at = 0; at < bytes.size(); at += dl::kReportSize) {
      dl::Report r{};
      for (std::size_t i = 0; i < dl::kReportSize && at + i < bytes.size(); ++i)
        r[i] = bytes[at + i];
      replies_.push_back(r);
    }
  }

  void handle(const std::vector<std::uint8_t>& m) {
    const std::uint8_t flags = m[0], seq = m[1];
    const std::uint16_t cmd = static_cast<std::uint16_t>(m[4] | (m[5] << 8));
    const std::vector<std::uint8_t> data(m.begin() + 6, m.end());
    if (s_.silent.count(cmd)) return;
    if (s_.nack.count(cmd)) {
      reply(static_cast<std::uint8_t>(flags | dl::kFlagError), seq, {});
      return;
    }
    const bool is_read = flags & dl::kFlagRead;
    if (!is_read) {
      if (!(cmd == 0x1A05 && s_.led_pwm_stuck)) s_.registers[cmd] = data;
      if (cmd == 0x1A34) s_.mailbox_writes.push_back(data);
      if (cmd == 0x1A1A) validation_polls_ = 0;
      if (flags & dl::kFlagReply) reply(flags, seq, {});
      return;
    }
    std::vector<std::uint8_t> out;
    auto reg = [&](std::size_t n) {
      auto it = s_.registers.find(cmd);
      out = it != s_.registers.end() ? it->second : std::vector<std::uint8_t>{};
      out.resize(n, 0);
    };
    switch (cmd) {
      case 0x0205:  // version: app 5.1.0, api 3.0.0, ...
        out = {0x00, 0x00, 0x01, 0x05, 0, 0, 0, 3, 1, 0, 0, 1, 2, 0, 0, 1};
        break;
      case 0x0200:
        if (s_.standby_polls > 0) {
          --s_.standby_polls;
          out = {1};
        } else {
          out = {0};
        }
        break;
      case 0x1A0A:
        out = {s_.hardware_status};
        break;
      case 0x1A0B:
        out = {s_.system_status};
        break;
      case 0x1A0C:
        out = {s_.main_status};
        break;
      case 0x1A42:
        out = {static_cast<std::uint8_t>(s_.images_in_flash)};
        break;
      case 0x1A1A:
        out = {static_cast<std::uint8_t>(
            validation_polls_++ < s_.validation_busy_polls ? 0x80 : s_.validation_bits)};
        break;
      case 0x1A29:
        reg(8);
        break;
      case 0x1A05: {
        auto it = s_.registers.find(cmd);
        out = {it != s_.registers.end() && !it->second.empty() ? it->second[0]
                                                               : s_.led_pwm_default};
        break;
      }
      case 0x1A31:
        reg(4);
        break;
      case 0x0B01:
        reg(3);
        break;
      case 0x1A34: {  // long read: 100 bytes, spans two reports
        for (int i = 0; i < 100; ++i) out.push_back(static_cast<std::uint8_t>(i));
        break;
      }
      default:
        reg(1);
        break;
    }
    reply(flags, seq, out);
  }

  FakeDlpc350State& s_;
  std::vector<std::uint8_t> pending_;
  std::size_t expected_ = 0;
  std::vector<dl::Report> replies_;
  int validation_polls_ = 0;
};

}  // namespace sl::test
