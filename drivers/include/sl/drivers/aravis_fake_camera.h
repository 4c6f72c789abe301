// An in-process GigE Vision camera: Aravis' fake GigE Vision camera
// (ArvGvFakeCamera) listening on a local interface, serving GVCP and sending
// GVSP like a real camera, whose frames carry images given by the caller.
// Used by the tests and by the daemon's `sensor: fake_gige` mode to run the
// real AravisCamera path without hardware.
//
// Each queued image is sent as one frame, in order, with the given device
// timestamp (the fake camera's clock runs at 1 GHz, so the timestamp reaches
// the receiver unchanged). The camera must be configured by its client for
// TriggerMode On / TriggerSource Software: a frame is sent when a trigger
// arrives, either the client's TriggerSoftware command over GVCP or trigger()
// here (the in-process equivalent of a trigger line).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include <opencv2/core/mat.hpp>

#include "sl/pipeline/types.h"

namespace sl::drivers {

struct FakeGigeOptions {
  std::string interface_address = "127.0.0.1";  // the interface it listens on (GVCP port 3956)
  std::string serial = "SL-FAKE-1";             // Aravis device id = "Aravis-Fake-" + serial
  // How often the fake camera checks for a software trigger: the trigger to
  // send latency is at most one period.
  double trigger_poll_hz = 1000;
  std::size_t max_queued = 16;  // frames waiting to be sent; the oldest is dropped beyond
};

struct FakeGigeCounters {
  std::uint64_t frames_sent = 0;       // filled with a queued image
  std::uint64_t frames_unfilled = 0;   // triggered with no image queued (sent black)
  std::uint64_t frames_mismatched = 0; // queued image of another size / depth (sent black)
  std::uint64_t queue_dropped = 0;     // oldest queued images dropped
};

// Thread-safe: queue()/trigger() from any thread; the fill runs on Aravis'
// fake camera thread.
class FakeGigeCamera {
 public:
  // Throws std::runtime_error if the camera cannot listen (no such
  // interface, or GVCP port 3956 on it is taken, e.g. by another fake camera).
  explicit FakeGigeCamera(const FakeGigeOptions& options);
  ~FakeGigeCamera();
  FakeGigeCamera(const FakeGigeCamera&) = delete;
  FakeGigeCamera& operator=(const FakeGigeCamera&) = delete;

  std::string deviceId() const;  // "Aravis-Fake-<serial>"
  const FakeGigeOptions& options() const;

  // Queues `image` (CV_8UC1 for Mono8, CV_16UC1 for Mono16; the size the
  // client configured) to be sent with device timestamp `device_stamp_ns`.
  void queue(cv::Mat image, std::uint64_t device_stamp_ns);
  // Triggers the camera as its trigger line would (sends the next queued
  // image, if the client has started the acquisition).
  void trigger();
  // queue() then trigger().
  void push(cv::Mat image, std::uint64_t device_stamp_ns);
  // Fraction of GVSP packets the fake camera drops (0..1), to exercise the
  // receiver's incomplete-frame handling.
  void setLostPacketRatio(double ratio);

  FakeGigeCounters counters() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::drivers
