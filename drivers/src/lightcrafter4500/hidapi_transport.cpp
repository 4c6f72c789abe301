// hidapi implementation of dlpc350::HidTransport (hidraw backend: the kernel's
// usbhid driver stays attached; access rights come from
// systemd/99-lightcrafter4500.rules).
#include <hidapi/hidapi.h>

#include <cstdio>
#include <mutex>
#include <string>

#include "sl/drivers/lightcrafter4500.h"

namespace sl::drivers {

namespace {

std::string narrow(const wchar_t* w) {
  if (!w) return "unknown error";
  std::string s;
  for (; *w; ++w) s += (*w >= 32 && *w < 127) ? static_cast<char>(*w) : '?';
  return s;
}

std::string usbId(std::uint16_t vendor, std::uint16_t product) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%04x:%04x", vendor, product);
  return buf;
}

// Thread-compatible (one per device; the projector serialises access).
class HidapiTransport : public dlpc350::HidTransport {
 public:
  HidapiTransport(hid_device* device, std::string name) : device_(device), name_(std::move(name)) {}
  ~HidapiTransport() override { hid_close(device_); }
  HidapiTransport(const HidapiTransport&) = delete;
  HidapiTransport& operator=(const HidapiTransport&) = delete;

  void write(const dlpc350::Report& report) override {
    unsigned char buf[1 + dlpc350::kReportSize];
    buf[0] = 0;  // report id: the DLPC350 uses unnumbered reports
    std::copy(report.begin(), report.end(), buf + 1);
    if (hid_write(device_, buf, sizeof buf) < 0)
      throw dlpc350::HidError(name_ +
                              ": USB write failed (unplugged?): " + narrow(hid_error(device_)));
  }

  std::optional<dlpc350::Report> read(std::chrono::milliseconds timeout) override {
    dlpc350::Report r{};
    const int n = hid_read_timeout(device_, r.data(), r.size(), static_cast<int>(timeout.count()));
    if (n < 0)
      throw dlpc350::HidError(name_ +
                              ": USB read failed (unplugged?): " + narrow(hid_error(device_)));
    if (n == 0) return std::nullopt;
    return r;
  }

 private:
  hid_device* device_;
  std::string name_;
};

}  // namespace

std::unique_ptr<dlpc350::HidTransport> openHidapiTransport(std::uint16_t vendor_id,
                                                           std::uint16_t product_id,
                                                           const std::string& serial) {
  static std::once_flag init_once;
  static int init_result = 0;
  std::call_once(init_once, [] { init_result = hid_init(); });
  const std::string name = "LightCrafter 4500 (USB " + usbId(vendor_id, product_id) +
                           (serial.empty() ? "" : ", serial " + serial) + ")";
  if (init_result != 0) throw dlpc350::HidError(name + ": hidapi initialisation failed");
  const std::wstring wserial(serial.begin(), serial.end());
  hid_device* device = hid_open(vendor_id, product_id, serial.empty() ? nullptr : wserial.c_str());
  if (!device)
    throw dlpc350::HidError(name +
                            " not found or not accessible: is it connected and powered, and may "
                            "this user open /dev/hidraw* (systemd/99-lightcrafter4500.rules)?");
  return std::make_unique<HidapiTransport>(device, name);
}

}  // namespace sl::drivers
