#include "sl/drivers/aravis_fake_camera.h"

#include <cstring>
#include <deque>
#include <mutex>
#include <stdexcept>

#include "arv_util.h"

namespace sl::drivers {

namespace {

// The fake camera's TriggerSoftware register (arvfakecamera.h): set to 1 to
// trigger; the fake camera clears it when it sends the frame.
constexpr guint32 kTriggerSoftwareRegister = ARV_FAKE_CAMERA_REGISTER_TRIGGER_SOFTWARE;

}  // namespace

struct FakeGigeCamera::Impl {
  FakeGigeOptions options;
  aravis::GObjectPtr<ArvGvFakeCamera> gv;
  ArvFakeCamera* fake = nullptr;  // owned by gv

  struct Queued {
    cv::Mat image;
    std::uint64_t stamp_ns = 0;
  };
  mutable std::mutex mutex;
  std::deque<Queued> queued;  // guarded by mutex
  FakeGigeCounters counters;  // guarded by mutex

  // Runs on the fake camera's thread with its fill mutex held.
  static void fill(ArvBuffer* buffer, void* self, guint32, guint32, ArvPixelFormat format) {
    static_cast<Impl*>(self)->fillBuffer(buffer, format);
  }

  void fillBuffer(ArvBuffer* buffer, ArvPixelFormat format) {
    const int width = arv_buffer_get_image_width(buffer);
    const int height = arv_buffer_get_image_height(buffer);
    // The fake camera allocates width * height * bytes per pixel; the data
    // size it reports is only set by its own fill pattern.
    std::size_t reported = 0;
    auto* data = static_cast<std::uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, &reported)));
    const int bytes = format == ARV_PIXEL_FORMAT_MONO_16 ? 2 : 1;
    const std::size_t size = static_cast<std::size_t>(width) * static_cast<std::size_t>(height) *
                             static_cast<std::size_t>(bytes);
    const int type = bytes == 2 ? CV_16UC1 : CV_8UC1;

    std::lock_guard lock(mutex);
    if (queued.empty()) {
      ++counters.frames_unfilled;
      std::memset(data, 0, size);
      return;
    }
    Queued next = std::move(queued.front());
    queued.pop_front();
    if (next.image.rows != height || next.image.cols != width || next.image.type() != type ||
        (format != ARV_PIXEL_FORMAT_MONO_8 && format != ARV_PIXEL_FORMAT_MONO_16)) {
      ++counters.frames_mismatched;
      std::memset(data, 0, size);
    } else {
      const std::size_t row = static_cast<std::size_t>(width) * static_cast<std::size_t>(bytes);
      for (int y = 0; y < height; ++y)
        std::memcpy(data + static_cast<std::size_t>(y) * row, next.image.ptr(y), row);
      ++counters.frames_sent;
    }
    arv_buffer_set_timestamp(buffer, next.stamp_ns);
    // One trigger per queued image: re-arm while images wait.
    if (!queued.empty()) arv_fake_camera_write_register(fake, kTriggerSoftwareRegister, 1);
  }
};

FakeGigeCamera::FakeGigeCamera(const FakeGigeOptions& options) : impl_(std::make_unique<Impl>()) {
  Impl& d = *impl_;
  d.options = options;
  if (options.serial.empty()) throw std::invalid_argument("fake GigE camera: empty serial");
  d.gv.reset(arv_gv_fake_camera_new(options.interface_address.c_str(), options.serial.c_str()));
  if (!d.gv || !arv_gv_fake_camera_is_running(d.gv.get()))
    throw std::runtime_error("fake GigE camera '" + options.serial + "': cannot listen on " +
                             options.interface_address +
                             " (no such interface, or GVCP port 3956 taken by another camera)");
  d.fake = arv_gv_fake_camera_get_fake_camera(d.gv.get());
  arv_fake_camera_set_trigger_frequency(d.fake, options.trigger_poll_hz);
  arv_fake_camera_set_fill_pattern(d.fake, &Impl::fill, &d);
}

FakeGigeCamera::~FakeGigeCamera() {
  // Stop the fake camera's thread before the fill data goes away.
  impl_->gv.reset();
}

std::string FakeGigeCamera::deviceId() const { return "Aravis-Fake-" + impl_->options.serial; }
const FakeGigeOptions& FakeGigeCamera::options() const { return impl_->options; }

void FakeGigeCamera::queue(cv::Mat image, std::uint64_t device_stamp_ns) {
  Impl& d = *impl_;
  std::lock_guard lock(d.mutex);
  d.queued.push_back({std::move(image), device_stamp_ns});
  while (d.queued.size() > d.options.max_queued) {
    d.queued.pop_front();
    ++d.counters.queue_dropped;
  }
}

void FakeGigeCamera::trigger() {
  arv_fake_camera_write_register(impl_->fake, kTriggerSoftwareRegister, 1);
}

void FakeGigeCamera::push(cv::Mat image, std::uint64_t device_stamp_ns) {
  queue(std::move(image), device_stamp_ns);
  trigger();
}

void FakeGigeCamera::setLostPacketRatio(double ratio) {
  g_object_set(impl_->gv.get(), "gvsp-lost-ratio", ratio, nullptr);
}

FakeGigeCounters FakeGigeCamera::counters() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->counters;
}

}  // namespace sl::drivers
