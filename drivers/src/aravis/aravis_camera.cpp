#include "sl/drivers/aravis_camera.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "arv_util.h"

namespace sl::drivers {

using aravis::GErrorPtr;
using aravis::GObjectPtr;

namespace {

using Clock = std::chrono::steady_clock;

std::string describeDevices() {
  std::string list;
  const unsigned n = arv_get_n_devices();
  for (unsigned i = 0; i < n; ++i) {
    list += (list.empty() ? "" : ", ") + aravis::str(arv_get_device_id(i)) + " (serial " +
            aravis::str(arv_get_device_serial_nbr(i)) + ", " +
            aravis::str(arv_get_device_address(i)) + ")";
  }
  return list.empty() ? "none" : list;
}

// The Aravis device id for an id, serial number or address; empty if no
// discovered device matches.
std::string resolveDeviceId(const std::string& spec) {
  arv_update_device_list();
  const unsigned n = arv_get_n_devices();
  for (unsigned i = 0; i < n; ++i) {
    if (spec == aravis::str(arv_get_device_id(i)) ||
        spec == aravis::str(arv_get_device_serial_nbr(i)) ||
        spec == aravis::str(arv_get_device_address(i)) ||
        spec == aravis::str(arv_get_device_physical_id(i)))
      return aravis::str(arv_get_device_id(i));
  }
  return {};
}

bool looksLikeIpv4(const std::string& s) {
  GInetAddress* address = g_inet_address_new_from_string(s.c_str());
  if (address == nullptr) return false;
  const bool v4 = g_inet_address_get_family(address) == G_SOCKET_FAMILY_IPV4;
  g_object_unref(address);
  return v4;
}

const char* edgeName(AravisTriggerConfig::Edge edge) {
  switch (edge) {
    case AravisTriggerConfig::Edge::kRising: return "RisingEdge";
    case AravisTriggerConfig::Edge::kFalling: return "FallingEdge";
    case AravisTriggerConfig::Edge::kAny: return "AnyEdge";
  }
  return "RisingEdge";
}

}  // namespace

// One open connection: the camera, its stream and the control-lost signal.
// Built and torn down by the grab thread (or open()).
struct Connection {
  GObjectPtr<ArvCamera> camera;
  GObjectPtr<ArvStream> stream;
  std::string device_id;
  int width = 0, height = 0;
  std::uint32_t pixel_format = 0;
  int bit_depth = 8;
  std::size_t payload = 0;
  gulong lost_handler = 0;
  std::vector<std::string> notes;
};

struct AravisCamera::Impl {
  explicit Impl(AravisCameraConfig c) : config(std::move(c)) {}
  ~Impl() { disconnect(); }

  const AravisCameraConfig config;

  mutable std::mutex mutex;
  std::unique_ptr<Connection> connection;  // guarded by mutex; replaced by the grab thread only
  AravisCounters counters;                 // guarded by mutex
  std::vector<std::string> notes;          // guarded by mutex
  std::string last_reconnect_error;        // grab thread only
  Clock::time_point last_attempt{};        // grab thread only
  int width = 0, height = 0;               // fixed by the first open

  std::atomic<bool> acquiring{false};
  std::atomic<bool> lost{false};  // set from Aravis' heartbeat thread
  std::atomic<std::uint64_t> stop_epoch{0};

  std::string who() const { return "camera '" + config.name + "' (" + config.device + ")"; }

  static void onControlLost(ArvDevice*, gpointer self) {
    static_cast<Impl*>(self)->lost.store(true);
  }

  // Opens and configures; throws std::runtime_error.
  std::unique_ptr<Connection> connect();
  void configure(Connection& c);
  void disconnect();  // mutex not held
  void startAcquisition(Connection& c);

  // Feature helpers: throw naming the feature when the camera rejects a value.
  bool available(Connection& c, const char* feature) {
    GErrorPtr error;
    const bool yes = arv_camera_is_feature_available(c.camera.get(), feature, error.out());
    return yes && !error;
  }
  void check(GErrorPtr& error, const std::string& what) {
    if (error) throw std::runtime_error(who() + ": " + what + ": " + error.message());
  }
  void setEnum(Connection& c, const char* feature, const std::string& value) {
    GErrorPtr error;
    const char* current = arv_camera_get_string(c.camera.get(), feature, error.out());
    if (!error && current != nullptr && value == current) return;
    error.reset();
    arv_camera_set_string(c.camera.get(), feature, value.c_str(), error.out());
    check(error, std::string("cannot set ") + feature + " to " + value);
  }
  void setBool(Connection& c, const char* feature, bool value) {
    GErrorPtr error;
    const bool current = arv_camera_get_boolean(c.camera.get(), feature, error.out());
    if (!error && current == value) return;
    error.reset();
    arv_camera_set_boolean(c.camera.get(), feature, value, error.out());
    check(error, std::string("cannot set ") + feature + " to " + (value ? "true" : "false"));
  }
  void setFloat(Connection& c, const char* feature, double value) {
    GErrorPtr error;
    const double current = arv_camera_get_float(c.camera.get(), feature, error.out());
    if (!error && current == value) return;
    error.reset();
    arv_camera_set_float(c.camera.get(), feature, value, error.out());
    check(error, std::string("cannot set ") + feature + " to " + std::to_string(value));
  }
  // Switches an optional feature; a camera without it gets a note.
  template <typename Setter>
  void optional(Connection& c, const char* feature, const std::string& setting, Setter set) {
    if (!available(c, feature)) {
      c.notes.push_back(std::string("camera lacks ") + feature + ": '" + setting + "' skipped");
      return;
    }
    set();
  }
};

std::unique_ptr<Connection> AravisCamera::Impl::connect() {
  // An address is opened directly (GVCP to that address only); an id or a
  // serial number needs Aravis' discovery, which broadcasts on every interface.
  const std::string device_id =
      looksLikeIpv4(config.device) ? config.device : resolveDeviceId(config.device);
  if (device_id.empty())
    throw std::runtime_error(who() + ": no camera with this id, serial number or address (found: " +
                             describeDevices() + ")");
  auto c = std::make_unique<Connection>();
  GErrorPtr error;
  c->camera.reset(arv_camera_new(device_id.c_str(), error.out()));
  if (!c->camera) {
    throw std::runtime_error(who() + ": cannot open " + device_id + ": " +
                             (error ? error.message() : std::string("unknown error")));
  }
  c->device_id = device_id;
  ArvDevice* device = arv_camera_get_device(c->camera.get());
  c->lost_handler = g_signal_connect(device, "control-lost", G_CALLBACK(&Impl::onControlLost), this);
  lost.store(false);
  configure(*c);
  return c;
}

void AravisCamera::Impl::configure(Connection& c) {
  ArvCamera* cam = c.camera.get();
  GErrorPtr error;
  arv_camera_stop_acquisition(cam, error.out());  // a previous owner may have left it running
  error.reset();

  if (arv_camera_is_gv_device(cam)) {
    arv_camera_gv_set_stream_options(cam, config.packet_socket
                                              ? ARV_GV_STREAM_OPTION_NONE
                                              : ARV_GV_STREAM_OPTION_PACKET_SOCKET_DISABLED);
    if (config.packet_size > 0) {
      arv_camera_gv_set_packet_size_adjustment(cam, ARV_GV_PACKET_SIZE_ADJUSTMENT_NEVER);
      arv_camera_gv_set_packet_size(cam, config.packet_size, error.out());
      check(error, "cannot set packet size " + std::to_string(config.packet_size));
    } else {
      arv_camera_gv_auto_packet_size(cam, error.out());
      check(error, "cannot negotiate the packet size");
    }
  }

  // Binning before the region: it changes the region's bounds.
  if (config.binning_horizontal != 1 || config.binning_vertical != 1 ||
      arv_camera_is_binning_available(cam, nullptr)) {
    if (!arv_camera_is_binning_available(cam, nullptr)) {
      c.notes.push_back("camera lacks binning: " + std::to_string(config.binning_horizontal) +
                        "x" + std::to_string(config.binning_vertical) + " skipped");
    } else {
      arv_camera_set_binning(cam, config.binning_horizontal, config.binning_vertical,
                             error.out());
      check(error, "cannot set binning " + std::to_string(config.binning_horizontal) + "x" +
                       std::to_string(config.binning_vertical));
    }
  }

  arv_camera_set_pixel_format_from_string(cam, config.pixel_format.c_str(), error.out());
  check(error, "cannot set PixelFormat " + config.pixel_format);
  c.pixel_format = static_cast<std::uint32_t>(arv_camera_get_pixel_format(cam, error.out()));
  check(error, "cannot read PixelFormat");
  c.bit_depth = monoBitDepth(c.pixel_format);
  if (c.bit_depth == 0 || c.pixel_format != monoPixelFormatCode(config.pixel_format))
    throw std::runtime_error(who() + ": PixelFormat " + config.pixel_format +
                             " was not applied (camera reports " +
                             aravis::hex(c.pixel_format) + ")");

  // Region: width/height 0 = as large as the sensor allows from the offset.
  gint min_w = 0, max_w = 0, min_h = 0, max_h = 0;
  // Offsets to 0 first so that the bounds are the sensor's (a previous owner
  // may have left an offset); a camera without offsets keeps its full frame.
  if (available(c, "OffsetX")) arv_camera_set_integer(cam, "OffsetX", 0, nullptr);
  if (available(c, "OffsetY")) arv_camera_set_integer(cam, "OffsetY", 0, nullptr);
  arv_camera_get_width_bounds(cam, &min_w, &max_w, error.out());
  check(error, "cannot read the Width bounds");
  arv_camera_get_height_bounds(cam, &min_h, &max_h, error.out());
  check(error, "cannot read the Height bounds");
  const int w = config.width > 0 ? config.width : max_w - config.offset_x;
  const int h = config.height > 0 ? config.height : max_h - config.offset_y;
  if (config.offset_x < 0 || config.offset_y < 0 || w <= 0 || h <= 0 ||
      config.offset_x + w > max_w || config.offset_y + h > max_h)
    throw std::runtime_error(who() + ": region " + std::to_string(w) + "x" + std::to_string(h) +
                             "+" + std::to_string(config.offset_x) + "+" +
                             std::to_string(config.offset_y) + " exceeds the sensor's " +
                             std::to_string(max_w) + "x" + std::to_string(max_h));
  arv_camera_set_region(cam, config.offset_x, config.offset_y, w, h, error.out());
  check(error, "cannot set the region " + std::to_string(w) + "x" + std::to_string(h) + "+" +
                   std::to_string(config.offset_x) + "+" + std::to_string(config.offset_y));
  gint x = 0, y = 0, rw = 0, rh = 0;
  arv_camera_get_region(cam, &x, &y, &rw, &rh, error.out());
  check(error, "cannot read the region back");
  if (x != config.offset_x || y != config.offset_y || rw != w || rh != h)
    throw std::runtime_error(who() + ": region " + std::to_string(w) + "x" + std::to_string(h) +
                             "+" + std::to_string(config.offset_x) + "+" +
                             std::to_string(config.offset_y) + " was adjusted by the camera to " +
                             std::to_string(rw) + "x" + std::to_string(rh) + "+" +
                             std::to_string(x) + "+" + std::to_string(y) +
                             " (check the increments)");
  c.width = rw;
  c.height = rh;

  // Linear intensity response (paper section 3.3): every automatic or
  // non-linear processing off. Features the camera lacks are noted.
  optional(c, "ExposureAuto", "Off", [&] { setEnum(c, "ExposureAuto", "Off"); });
  optional(c, "GainAuto", "Off", [&] { setEnum(c, "GainAuto", "Off"); });
  optional(c, "BlackLevelAuto", "Off", [&] { setEnum(c, "BlackLevelAuto", "Off"); });
  optional(c, "BalanceWhiteAuto", "Off", [&] { setEnum(c, "BalanceWhiteAuto", "Off"); });
  if (available(c, "GammaEnable")) {
    setBool(c, "GammaEnable", false);
  } else {
    optional(c, "Gamma", "1.0", [&] { setFloat(c, "Gamma", 1.0); });
  }
  optional(c, "LUTEnable", "false", [&] { setBool(c, "LUTEnable", false); });

  if (config.exposure_us) {
    if (!arv_camera_is_exposure_time_available(cam, nullptr)) {
      c.notes.push_back("camera lacks an exposure time: " + std::to_string(*config.exposure_us) +
                        " us skipped");
    } else {
      arv_camera_set_exposure_time(cam, *config.exposure_us, error.out());
      check(error, "cannot set the exposure time to " + std::to_string(*config.exposure_us) + " us");
    }
  }
  if (config.gain) {
    if (!arv_camera_is_gain_available(cam, nullptr)) {
      c.notes.push_back("camera lacks a gain: " + std::to_string(*config.gain) + " skipped");
    } else {
      arv_camera_set_gain(cam, *config.gain, error.out());
      check(error, "cannot set the gain to " + std::to_string(*config.gain));
    }
  }

  // Trigger.
  if (available(c, "AcquisitionMode")) setEnum(c, "AcquisitionMode", "Continuous");
  using Mode = AravisTriggerConfig::Mode;
  if (config.trigger.mode == Mode::kFreeRun) {
    if (available(c, "TriggerSelector")) setEnum(c, "TriggerSelector", "FrameStart");
    optional(c, "TriggerMode", "Off", [&] { setEnum(c, "TriggerMode", "Off"); });
    if (config.trigger.frame_rate_hz > 0) {
      arv_camera_set_frame_rate(cam, config.trigger.frame_rate_hz, error.out());
      check(error, "cannot set the frame rate to " + std::to_string(config.trigger.frame_rate_hz));
    }
  } else {
    if (!available(c, "TriggerMode"))
      throw std::runtime_error(who() + ": camera has no TriggerMode; use trigger mode free_run");
    if (available(c, "TriggerSelector")) setEnum(c, "TriggerSelector", "FrameStart");
    setEnum(c, "TriggerMode", "On");
    if (config.trigger.mode == Mode::kSoftware) {
      setEnum(c, "TriggerSource", "Software");
      GErrorPtr support_error;
      if (!arv_camera_is_software_trigger_supported(cam, support_error.out()) || support_error)
        throw std::runtime_error(who() + ": TriggerSoftware: the camera has no software trigger " +
                                 "command; use trigger mode hardware or free_run");
    } else {
      setEnum(c, "TriggerSource", config.trigger.line);
      optional(c, "TriggerActivation", edgeName(config.trigger.edge),
               [&] { setEnum(c, "TriggerActivation", edgeName(config.trigger.edge)); });
    }
  }

  c.payload = static_cast<std::size_t>(arv_camera_get_payload(cam, error.out()));
  check(error, "cannot read PayloadSize");

  c.stream.reset(arv_camera_create_stream(cam, nullptr, nullptr, error.out()));
  if (!c.stream) {
    throw std::runtime_error(who() + ": cannot create the stream: " +
                             (error ? error.message() : std::string("unknown error")));
  }
  if (ARV_IS_GV_STREAM(c.stream.get())) {
    if (config.socket_buffer_bytes > 0) {
      g_object_set(c.stream.get(), "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED,
                   "socket-buffer-size", static_cast<gint>(config.socket_buffer_bytes), nullptr);
    } else {
      g_object_set(c.stream.get(), "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_AUTO, nullptr);
    }
    if (config.frame_retention_ms > 0)
      g_object_set(c.stream.get(), "frame-retention",
                   static_cast<guint>(config.frame_retention_ms) * 1000u, nullptr);
  }
  for (int i = 0; i < config.buffer_count; ++i)
    arv_stream_push_buffer(c.stream.get(), arv_buffer_new_allocate(c.payload));
}

void AravisCamera::Impl::startAcquisition(Connection& c) {
  GErrorPtr error;
  arv_camera_start_acquisition(c.camera.get(), error.out());
  check(error, "cannot start the acquisition");
}

void AravisCamera::Impl::disconnect() {
  std::unique_ptr<Connection> c;
  {
    std::lock_guard lock(mutex);
    c = std::move(connection);
    counters.connected = false;
  }
  if (!c) return;
  if (c->lost_handler != 0)
    g_signal_handler_disconnect(arv_camera_get_device(c->camera.get()), c->lost_handler);
  if (!lost.load()) arv_camera_stop_acquisition(c->camera.get(), nullptr);
  // Releasing the stream stops its thread; the camera releases the control
  // channel (which times out on a lost device).
  c->stream.reset();
  c->camera.reset();
}

std::shared_ptr<AravisCamera> AravisCamera::open(const AravisCameraConfig& config) {
  if (config.name.empty()) throw std::invalid_argument("AravisCamera: empty camera name");
  if (monoPixelFormatCode(config.pixel_format) == 0)
    throw std::invalid_argument("camera '" + config.name + "': unsupported pixel format '" +
                                config.pixel_format + "'");
  if (config.buffer_count < 2) throw std::invalid_argument("camera '" + config.name + "': buffer_count must be >= 2");
  auto impl = std::make_unique<Impl>(config);
  auto c = impl->connect();
  impl->width = c->width;
  impl->height = c->height;
  impl->notes = c->notes;
  impl->counters.connected = true;
  impl->connection = std::move(c);
  return std::shared_ptr<AravisCamera>(new AravisCamera(std::move(impl)));
}

AravisCamera::AravisCamera(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
AravisCamera::~AravisCamera() = default;

std::string AravisCamera::id() const { return impl_->config.name; }
int AravisCamera::width() const { return impl_->width; }
int AravisCamera::height() const { return impl_->height; }

void AravisCamera::start() {
  Impl& d = *impl_;
  std::lock_guard lock(d.mutex);
  if (d.acquiring.exchange(true)) return;
  if (d.connection) d.startAcquisition(*d.connection);
}

void AravisCamera::stop() {
  Impl& d = *impl_;
  ++d.stop_epoch;
  std::lock_guard lock(d.mutex);
  if (!d.acquiring.exchange(false)) return;
  if (d.connection && !d.lost.load()) arv_camera_stop_acquisition(d.connection->camera.get(), nullptr);
}

bool AravisCamera::hasSoftwareTrigger() const {
  return impl_->config.trigger.mode == AravisTriggerConfig::Mode::kSoftware;
}

void AravisCamera::triggerSoftware() {
  Impl& d = *impl_;
  if (!hasSoftwareTrigger()) {
    const bool line = d.config.trigger.mode == AravisTriggerConfig::Mode::kHardware;
    throw std::logic_error(
        d.who() + ": TriggerSoftware: the camera is configured for " +
        (line ? "trigger mode hardware (TriggerSource " + d.config.trigger.line + ")"
              : std::string("trigger mode free_run")) +
        "; software-triggered scans need trigger: {mode: software}");
  }
  std::lock_guard lock(d.mutex);
  if (!d.acquiring.load()) throw std::logic_error(d.who() + ": TriggerSoftware before start()");
  if (!d.connection || d.lost.load())
    throw std::runtime_error(d.who() + ": TriggerSoftware: the camera is not connected " +
                             "(lost; grab() reopens it)");
  GErrorPtr error;
  arv_camera_software_trigger(d.connection->camera.get(), error.out());
  d.check(error, "TriggerSoftware failed");
}

AravisCounters AravisCamera::counters() const {
  const Impl& d = *impl_;
  std::lock_guard lock(d.mutex);
  AravisCounters c = d.counters;
  if (d.connection && d.connection->stream) {
    guint64 completed = 0, failures = 0, underruns = 0;
    arv_stream_get_statistics(d.connection->stream.get(), &completed, &failures, &underruns);
    c.stream_underruns += underruns;
  }
  return c;
}

std::vector<std::string> AravisCamera::notes() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->notes;
}

std::string AravisCamera::deviceId() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->connection ? impl_->connection->device_id : std::string();
}

std::optional<Frame> AravisCamera::grab(std::chrono::milliseconds timeout) {
  Impl& d = *impl_;
  const auto deadline = Clock::now() + timeout;
  const std::uint64_t epoch = d.stop_epoch.load();

  // A lost camera: report once, then reopen at most every reconnect_interval_s.
  if (d.lost.load()) {
    bool had_connection = false;
    {
      std::lock_guard lock(d.mutex);
      had_connection = d.connection != nullptr;
    }
    if (had_connection) {
      {
        std::lock_guard lock(d.mutex);
        ++d.counters.connection_losses;
        // Stream underruns of the old stream are kept in the counters.
        guint64 completed = 0, failures = 0, underruns = 0;
        arv_stream_get_statistics(d.connection->stream.get(), &completed, &failures, &underruns);
        d.counters.stream_underruns += underruns;
      }
      d.disconnect();
      d.last_attempt = Clock::now();
      d.last_reconnect_error.clear();
      throw std::runtime_error(d.who() + ": connection lost (no heartbeat answer); reopening every " +
                               std::to_string(d.config.reconnect_interval_s) + " s");
    }
  }
  bool connected = false;
  {
    std::lock_guard lock(d.mutex);
    connected = d.connection != nullptr;
  }
  if (!connected) {
    const auto interval = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(d.config.reconnect_interval_s));
    if (Clock::now() - d.last_attempt < interval) {
      std::this_thread::sleep_until(std::min(deadline, d.last_attempt + interval));
      return std::nullopt;
    }
    d.last_attempt = Clock::now();
    try {
      auto c = d.connect();
      if (c->width != d.width || c->height != d.height)
        throw std::runtime_error(d.who() + ": reopened with size " + std::to_string(c->width) +
                                 "x" + std::to_string(c->height) + ", expected " +
                                 std::to_string(d.width) + "x" + std::to_string(d.height));
      std::lock_guard lock(d.mutex);
      if (d.acquiring.load()) d.startAcquisition(*c);
      d.notes = c->notes;
      d.connection = std::move(c);
      d.counters.connected = true;
      ++d.counters.reconnects;
      d.last_reconnect_error.clear();
    } catch (const std::exception& e) {
      const std::string message = std::string(e.what());
      if (message != d.last_reconnect_error) {
        d.last_reconnect_error = message;
        throw std::runtime_error("reopening failed: " + message);
      }
      return std::nullopt;
    }
  }

  // The grab thread is the only one that replaces the connection, so the
  // stream stays valid here without the mutex.
  Connection* c = nullptr;
  {
    std::lock_guard lock(d.mutex);
    c = d.connection.get();
  }
  while (true) {
    if (d.stop_epoch.load() != epoch) return std::nullopt;
    if (d.lost.load()) return std::nullopt;  // reported by the next grab()
    const auto now = Clock::now();
    if (now >= deadline) return std::nullopt;
    // Short slices so that stop() wakes us promptly.
    const auto slice = std::min<Clock::duration>(deadline - now, std::chrono::milliseconds(20));
    const auto slice_us = std::max<std::int64_t>(
        1, std::chrono::duration_cast<std::chrono::microseconds>(slice).count());
    ArvBuffer* buffer = arv_stream_timeout_pop_buffer(c->stream.get(), static_cast<guint64>(slice_us));
    if (buffer == nullptr) continue;

    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    std::optional<Frame> frame;
    {
      std::lock_guard lock(d.mutex);
      if (status == ARV_BUFFER_STATUS_TIMEOUT) {
        ++d.counters.buffers_timed_out;
      } else if (status != ARV_BUFFER_STATUS_SUCCESS) {
        ++d.counters.buffers_incomplete;
      } else if (arv_buffer_get_payload_type(buffer) != ARV_BUFFER_PAYLOAD_TYPE_IMAGE ||
                 arv_buffer_get_image_width(buffer) != c->width ||
                 arv_buffer_get_image_height(buffer) != c->height ||
                 static_cast<std::uint32_t>(arv_buffer_get_image_pixel_format(buffer)) !=
                     c->pixel_format) {
        ++d.counters.buffers_size_mismatch;
      } else {
        std::size_t size = 0;
        const void* data = arv_buffer_get_image_data(buffer, &size);
        Frame f;
        f.image = decodeMonoImage(data, size, c->width, c->height, c->pixel_format);
        if (f.image.empty()) {
          ++d.counters.buffers_size_mismatch;
        } else {
          const std::uint64_t device_ns = arv_buffer_get_timestamp(buffer);
          const auto host_ns = static_cast<std::int64_t>(arv_buffer_get_system_timestamp(buffer));
          f.stamp_ns = d.config.timestamp == AravisCameraConfig::Timestamp::kDevice
                           ? static_cast<pipeline::TimestampNs>(device_ns)
                           : host_ns - static_cast<std::int64_t>(std::llround(
                                           d.config.host_latency_s * 1e9));
          f.frame_id = arv_buffer_get_frame_id(buffer);
          f.bit_depth = c->bit_depth;
          ++d.counters.frames_delivered;
          d.counters.last_device_timestamp_ns = device_ns;
          d.counters.last_host_timestamp_ns = host_ns;
          frame = std::move(f);
        }
      }
    }
    arv_stream_push_buffer(c->stream.get(), buffer);
    if (frame) return frame;
  }
}

}  // namespace sl::drivers
