// GenICam cameras (GigE Vision, USB3 Vision) through Aravis 0.8.
//
// AravisCamera implements Camera: it opens a camera by Aravis device id,
// serial number or IP address, configures it for phase-shift profilometry
// (region, binning, pixel format, exposure, gain, trigger, and every feature
// that would break the linear intensity response switched off, paper
// section 3.3), and delivers complete frames only: incomplete or timed-out
// buffers are counted and dropped. A camera that disappears is reported by
// grab() (it throws once) and reopened and reconfigured when it returns.
//
// This header carries no glib/Aravis types: the Aravis objects live in
// drivers/src/aravis.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "sl/drivers/camera.h"

namespace sl::drivers {

struct AravisTriggerConfig {
  enum class Mode {
    kHardware,  // an input line (the VersaVIS on the real sensor)
    kSoftware,  // TriggerSoftware command (triggerSoftware(), or the fake camera's feeder)
    kFreeRun,   // TriggerMode Off, the camera's own frame rate
  };
  enum class Edge { kRising, kFalling, kAny };
  Mode mode = Mode::kHardware;
  std::string line = "Line0";  // TriggerSource for kHardware
  Edge edge = Edge::kRising;   // TriggerActivation for kHardware
  double frame_rate_hz = 0;    // kFreeRun: AcquisitionFrameRate; 0 = leave as is
};

struct AravisCameraConfig {
  std::string name;    // camera id in the pipeline and in messages, e.g. "top"
  std::string device;  // Aravis device id, serial number or IPv4 address
  // Region in (binned) pixels; width/height 0 = the largest from the offset.
  int offset_x = 0, offset_y = 0, width = 0, height = 0;
  int binning_horizontal = 1, binning_vertical = 1;
  // Mono8 (-> CV_8UC1); Mono10, Mono12, Mono16 (16-bit unpacked);
  // Mono10Packed, Mono12Packed (GigE Vision packing), Mono10p, Mono12p (PFNC
  // packing), unpacked to CV_16UC1.
  std::string pixel_format = "Mono8";
  std::optional<double> exposure_us;  // empty = leave as is
  std::optional<double> gain;         // camera units (dB for SFNC Gain); empty = leave as is
  AravisTriggerConfig trigger;
  // Frame::stamp_ns: kHost = the host system clock when the first packet of
  // the frame arrived, minus host_latency_s (exposure start to arrival);
  // kDevice = the camera's timestamp, which must run on the host's system
  // clock (IEEE 1588 / PTP synchronised with the host, or the fake camera).
  enum class Timestamp { kHost, kDevice };
  Timestamp timestamp = Timestamp::kHost;
  double host_latency_s = 0;
  // GigE Vision transport.
  int packet_size = 0;            // bytes; 0 = negotiate the largest the path allows
  bool packet_socket = true;      // Aravis' packet socket stream (needs CAP_NET_RAW); off on loopback
  std::size_t socket_buffer_bytes = 0;  // stream socket receive buffer; 0 = automatic (payload size)
  // GigE Vision stream: how long an unfinished frame waits for its missing
  // packets (after the last one received) before it is dropped as timed out;
  // 0 = Aravis' default (100 ms in 0.8).
  int frame_retention_ms = 0;
  int buffer_count = 16;          // frames in the stream's buffer pool
  double reconnect_interval_s = 1.0;  // between attempts to reopen a lost camera
};

// Counts since open(); frames that are never passed on are counted here.
struct AravisCounters {
  std::uint64_t frames_delivered = 0;
  std::uint64_t buffers_incomplete = 0;   // missing packets, wrong packet id, aborted
  std::uint64_t buffers_timed_out = 0;    // the frame's packets stopped arriving
  std::uint64_t buffers_size_mismatch = 0;  // not the configured size / format
  std::uint64_t stream_underruns = 0;     // no free buffer in the pool (Aravis statistics)
  std::uint64_t connection_losses = 0;
  std::uint64_t reconnects = 0;
  bool connected = false;
  std::uint64_t last_device_timestamp_ns = 0;  // of the last delivered frame
  std::int64_t last_host_timestamp_ns = 0;     // arrival on the host system clock
};

// Thread-safe: the daemon calls grab() from the camera thread and start(),
// stop(), triggerSoftware(), counters() from others. Only grab() reopens a
// lost camera.
class AravisCamera final : public Camera {
 public:
  // Opens and configures the camera. Throws std::runtime_error naming the
  // camera and the feature on failure (not found, a rejected setting).
  static std::shared_ptr<AravisCamera> open(const AravisCameraConfig& config);
  ~AravisCamera() override;
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  std::string id() const override;
  int width() const override;
  int height() const override;
  void start() override;
  void stop() override;
  // Next complete frame, or nullopt on timeout / after stop(). Throws
  // std::runtime_error once when the camera is lost (and again only for a
  // different reconnect failure); later calls try to reopen it.
  std::optional<Frame> grab(std::chrono::milliseconds timeout) override;

  // Software trigger: available when the camera was configured with trigger
  // mode kSoftware (TriggerMode On, TriggerSource Software), which open()
  // checks the camera supports. The source is fixed at open(): a camera wired
  // to a trigger line (kHardware) or free running answers false here, and
  // triggerSoftware() throws std::logic_error saying how to configure it.
  bool hasSoftwareTrigger() const override;
  // Executes the GenICam TriggerSoftware command: the camera exposes one
  // frame, which grab() delivers. Throws std::logic_error without software
  // trigger mode or before start(); std::runtime_error (naming the camera and
  // the command) when the camera is lost or refuses the command.
  void triggerSoftware() override;
  AravisCounters counters() const;
  // What configuration skipped or adapted ("camera lacks Gamma: skipped").
  std::vector<std::string> notes() const;
  std::string deviceId() const;  // the Aravis device id that was opened

  struct Impl;

 private:
  explicit AravisCamera(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Converts one monochrome image buffer to a cv::Mat (copied). `pfnc_format`
// is the GenICam PFNC pixel format code. Mono8 -> CV_8UC1; Mono10/12/16 and
// the packed Mono10Packed, Mono12Packed, Mono10p, Mono12p -> CV_16UC1 with the
// value in the low bits. Returns an empty Mat if the format is unsupported or
// `size` is smaller than the image needs.
cv::Mat decodeMonoImage(const void* data, std::size_t size, int width, int height,
                        std::uint32_t pfnc_format);
// Significant bits of a supported mono format (8, 10, 12, 16), 0 otherwise.
int monoBitDepth(std::uint32_t pfnc_format);
// PFNC code of a pixel format name accepted by AravisCameraConfig, 0 if unknown.
std::uint32_t monoPixelFormatCode(const std::string& name);

}  // namespace sl::drivers
