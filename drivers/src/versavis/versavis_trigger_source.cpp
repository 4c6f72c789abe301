#include <fcntl.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include "sl/drivers/versavis.h"

namespace sl::drivers {

namespace serial_detail {
bool setCustomBaud(int fd, int baud);  // serial_baud.cpp
}

namespace {

constexpr std::size_t kMaxBoardTimes = 256;             // per camera channel (8 s at 30 Hz)
constexpr std::chrono::milliseconds kRebootRetry{100};  // reopen retries after our reset

std::optional<speed_t> standardBaud(int baud) {
  switch (baud) {
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    case 460800:
      return B460800;
    case 500000:
      return B500000;
    case 921600:
      return B921600;
    case 1000000:
      return B1000000;
    default:
      return std::nullopt;
  }
}

std::int64_t realtimeNs() {
  timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

std::string ms(std::chrono::milliseconds d) { return std::to_string(d.count()) + " ms"; }

}  // namespace

VersavisTriggerSource::VersavisTriggerSource(VersavisConfig config, Log log)
    : config_(std::move(config)), log_(std::move(log)) {
  if (config_.baud <= 0) throw std::invalid_argument("VersaVIS: baud must be > 0");
  if (config_.triggers_per_sequence < 1)
    throw std::invalid_argument("VersaVIS: triggers_per_sequence must be >= 1");
  if (config_.init_matches < 1) throw std::invalid_argument("VersaVIS: init_matches must be >= 1");
  for (const std::string& prefix : config_.camera_channels) {
    if (prefix.empty()) throw std::invalid_argument("VersaVIS: empty camera channel topic");
    std::size_t index = channels_.size();
    for (std::size_t c = 0; c < channels_.size(); ++c)
      if (channels_[c].prefix == prefix) index = c;
    if (index == channels_.size()) {
      Channel c;
      c.prefix = prefix;
      channels_.push_back(std::move(c));
    }
    CameraState cam;
    cam.channel = index;
    cameras_.push_back(cam);
  }
  wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw std::runtime_error(std::string("eventfd: ") + std::strerror(errno));
  std::string error;
  if (!tryOpen(&error)) {
    close(wake_fd_);
    throw std::runtime_error(error);
  }
}

VersavisTriggerSource::~VersavisTriggerSource() {
  // rosserial_python's shutdown: TX_STOP tells the board the host is gone
  // (it stops publishing and waits for the next topic request).
  if (fd_ >= 0 && config_.tx_stop_at_close)
    writeAll(rosserial::encodeFrame(rosserial::kTopicTxStop, {}));
  closeDevice();
  if (wake_fd_ >= 0) close(wake_fd_);
}

void VersavisTriggerSource::note(int level, const std::string& message) const {
  if (log_) log_(level, "VersaVIS " + config_.device + ": " + message);
}

void VersavisTriggerSource::count(std::uint64_t VersavisCounters::*field, std::uint64_t n) {
  std::lock_guard lock(counters_mutex_);
  counters_.*field += n;
}

bool VersavisTriggerSource::tryOpen(std::string* error) {
  const std::string name = "VersaVIS " + config_.device;
  const int fd = open(config_.device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    *error = name + ": cannot open: " + std::strerror(errno);
    return false;
  }
  termios tio{};
  if (tcgetattr(fd, &tio) != 0) {
    *error = name + ": not a serial device: " + std::strerror(errno);
    close(fd);
    return false;
  }
  cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  const auto speed = standardBaud(config_.baud);
  if (speed) cfsetspeed(&tio, *speed);
  if (tcsetattr(fd, TCSANOW, &tio) != 0 ||
      (!speed && !serial_detail::setCustomBaud(fd, config_.baud))) {
    *error = name + ": cannot set raw mode at " + std::to_string(config_.baud) +
             " baud: " + std::strerror(errno);
    close(fd);
    return false;
  }
  tcflush(fd, TCIOFLUSH);
  fd_ = fd;
  connected_ = true;
  parser_.clear();
  resetSession();
  count(&VersavisCounters::connects);
  sendTopicRequest();
  return true;
}

void VersavisTriggerSource::resetSession() {
  trigger_topic_.reset();
  first_number_.reset();
  known_topics_.clear();
  last_time_request_ = last_packet_ = Clock::now();
  {
    std::lock_guard lock(counters_mutex_);
    counters_.silent = false;
  }
  std::lock_guard lock(cameras_mutex_);
  for (Channel& c : channels_) {
    c.time_topic.reset();
    c.init_topic.reset();
    c.times.clear();
    c.init_sent = false;
  }
  for (CameraState& c : cameras_) {
    const std::size_t channel = c.channel;
    c = CameraState();
    c.channel = channel;
  }
  outbox_.clear();
  cameras_cv_.notify_all();
}

void VersavisTriggerSource::closeDevice() {
  if (fd_ >= 0) close(fd_);
  fd_ = -1;
  connected_ = false;
}

void VersavisTriggerSource::writeAll(const std::vector<std::uint8_t>& bytes) {
  std::size_t done = 0;
  for (int tries = 0; done < bytes.size() && tries < 100; ++tries) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
    } else if (n < 0 && errno != EAGAIN && errno != EINTR) {
      return;  // the read side notices the hang-up
    } else {
      pollfd p{fd_, POLLOUT, 0};
      poll(&p, 1, 10);
    }
  }
}

void VersavisTriggerSource::sendTopicRequest() {
  writeAll(rosserial::encodeFrame(rosserial::kTopicPublisher, {}));
  next_negotiation_ = Clock::now() + config_.negotiation_retry;
  count(&VersavisCounters::topic_requests);
}

void VersavisTriggerSource::handleTopicInfo(const rosserial::TopicInfo& info, bool subscriber) {
  // Which topic and type this driver expects under that name, if any.
  std::string expected_type, expected_md5;
  Channel* camera_channel = nullptr;
  bool is_trigger = false, is_reset = false;
  if (!subscriber && info.topic_name == config_.topic) {
    is_trigger = true;
    expected_type = config_.message_type;
    expected_md5 =
        config_.message_type == rosserial::kTimeNumberedType ? rosserial::kTimeNumberedMd5 : "";
  } else if (subscriber && info.topic_name == config_.reset_topic) {
    is_reset = true;
    expected_type = rosserial::kBoolType;
    expected_md5 = rosserial::kBoolMd5;
  }
  std::unique_lock lock(cameras_mutex_);
  for (Channel& c : channels_) {
    if (!subscriber && info.topic_name == c.prefix + "image_time") {
      camera_channel = &c;
      expected_type = rosserial::kTimeNumberedType;
      expected_md5 = rosserial::kTimeNumberedMd5;
    } else if (subscriber && info.topic_name == c.prefix + "init") {
      camera_channel = &c;
      expected_type = rosserial::kBoolType;
      expected_md5 = rosserial::kBoolMd5;
    }
  }
  if (!subscriber) known_topics_.insert(info.topic_id);
  if (expected_type.empty()) return;  // other sensors (IMU, ...): not ours
  const std::string what =
      std::string(subscriber ? "subscriber" : "topic") + " '" + info.topic_name + "'";
  if (info.message_type != expected_type) {
    if (is_trigger) trigger_topic_.reset();
    lock.unlock();
    throw std::runtime_error("VersaVIS " + config_.device + ": " + what + " has type '" +
                             info.message_type + "', expected '" + expected_type + "'");
  }
  if (!expected_md5.empty() && info.md5sum != expected_md5) {
    // rosserial_python refuses such a topic too ("Mismatched md5sum"): the
    // firmware was built against another message definition.
    if (is_trigger) trigger_topic_.reset();
    lock.unlock();
    count(&VersavisCounters::md5_mismatches);
    throw std::runtime_error("VersaVIS " + config_.device + ": " + what + " of type '" +
                             info.message_type + "' has md5 " + info.md5sum + ", expected " +
                             expected_md5 + " (firmware built with another message definition)");
  }
  if (is_trigger) trigger_topic_ = info.topic_id;
  if (camera_channel) {
    if (subscriber)
      camera_channel->init_topic = info.topic_id;
    else
      camera_channel->time_topic = info.topic_id;
  }
  if (is_reset && config_.reset_at_start && !reset_sent_) {
    // sl_sensor resets the board at start: a fresh filter and handshake.
    // It reboots and hangs up the serial device; next() reconnects quietly.
    reset_sent_ = true;
    expect_hangup_ = true;
    outbox_.push_back(rosserial::encodeFrame(info.topic_id, rosserial::encodeBool(true)));
    count(&VersavisCounters::resets_sent);
    lock.unlock();
    note(1, "reset sent on '" + info.topic_name + "' (the board reboots and reconnects)");
  }
}

void VersavisTriggerSource::handle(const rosserial::Frame& frame) {
  count(&VersavisCounters::packets);
  last_packet_ = Clock::now();
  if (frame.topic_id == rosserial::kTopicTime) {
    // A time request (empty) from the board: answer with the host clock.
    writeAll(rosserial::encodeFrame(rosserial::kTopicTime, rosserial::encodeTime(realtimeNs())));
    last_time_request_ = Clock::now();
    count(&VersavisCounters::time_requests);
    return;
  }
  if (frame.topic_id == rosserial::kTopicPublisher ||
      frame.topic_id == rosserial::kTopicSubscriber) {
    const auto info = rosserial::decodeTopicInfo(frame.message);
    if (!info) {
      count(&VersavisCounters::malformed);
      return;
    }
    handleTopicInfo(*info, frame.topic_id == rosserial::kTopicSubscriber);
    return;
  }
  if (frame.topic_id == rosserial::kTopicLog) {
    const auto m = rosserial::decodeLog(frame.message);
    if (!m) {
      count(&VersavisCounters::malformed);
      return;
    }
    count(&VersavisCounters::log_messages);
    note(m->level, "board: " + m->text);
    return;
  }
  if (frame.topic_id < rosserial::kFirstUserTopic) return;  // other rosserial services
  if (!known_topics_.count(frame.topic_id)) {
    // rosserial_python: a publisher it does not know means the board has
    // another session's ids (e.g. it rebooted): ask for the topics again.
    count(&VersavisCounters::unknown_topics);
    if (Clock::now() >= next_negotiation_) {
      note(2, "packet on topic id " + std::to_string(frame.topic_id) +
                  ", which was not negotiated: requesting the topics again");
      count(&VersavisCounters::renegotiations);
      sendTopicRequest();
    }
    return;
  }
  if (trigger_topic_ && frame.topic_id == *trigger_topic_) {
    const auto m = rosserial::decodeTimeNumbered(frame.message);
    if (!m) {
      count(&VersavisCounters::malformed);
      return;
    }
    if (!first_number_) first_number_ = m->number;
    const std::uint64_t since_first = m->number - *first_number_;
    const auto per = static_cast<std::uint64_t>(config_.triggers_per_sequence);
    if (since_first % per != 0) return;
    TriggerEvent e;
    e.stamp_ns = static_cast<std::int64_t>(m->secs) * 1000000000 + m->nsecs + config_.offset_ns;
    e.sequence_index = since_first / per;
    pending_.push_back(e);
    pending_arrival_.push_back(realtimeNs());
    return;
  }
  std::lock_guard lock(cameras_mutex_);
  for (Channel& c : channels_) {
    if (!c.time_topic || frame.topic_id != *c.time_topic) continue;
    const auto m = rosserial::decodeTimeNumbered(frame.message);
    if (!m) {
      std::lock_guard counters_lock(counters_mutex_);
      ++counters_.malformed;
      return;
    }
    c.times.push_back(BoardTime{
        m->number, static_cast<std::int64_t>(m->secs) * 1000000000 + m->nsecs, realtimeNs()});
    if (c.times.size() > kMaxBoardTimes) c.times.pop_front();
    {
      std::lock_guard counters_lock(counters_mutex_);
      ++counters_.camera_times;
    }
    cameras_cv_.notify_all();
  }
}

RestampResult VersavisTriggerSource::restamp(std::size_t camera, std::uint64_t frame_id,
                                             std::int64_t arrival_ns, std::int64_t& stamp_ns) {
  if (camera >= cameras_.size())
    throw std::out_of_range("VersaVIS: camera " + std::to_string(camera) + " has no channel");
  std::string message;  // logged after the lock is released
  RestampResult result = RestampResult::kLearning;
  bool wake = false;  // outbox_ is read under cameras_mutex_ only (next() swaps it)
  {
    std::unique_lock lock(cameras_mutex_);
    CameraState& cam = cameras_[camera];
    Channel& ch = channels_[cam.channel];
    const auto frame = static_cast<std::int64_t>(frame_id);
    if (!cam.initialised) {
      // The board time that arrived last before this frame, if recent enough.
      const BoardTime* best = nullptr;
      for (const BoardTime& t : ch.times)
        if (t.arrival_ns <= arrival_ns &&
            arrival_ns - t.arrival_ns <= config_.max_arrival_delay.count() * 1000000)
          best = &t;
      if (best) {
        const std::int64_t offset = frame - static_cast<std::int64_t>(best->number);
        cam.matches = cam.offset && *cam.offset == offset ? cam.matches + 1 : 1;
        cam.offset = offset;
      } else {
        cam.matches = 0;
        cam.offset.reset();
      }
      if (cam.matches >= config_.init_matches) {
        cam.initialised = true;
        cam.misses = 0;
        message = "camera " + std::to_string(camera) + " matched board channel '" + ch.prefix +
                  "' (frame id - board number = " + std::to_string(*cam.offset) + ")";
        if (!ch.init_sent && ch.init_topic) {
          ch.init_sent = true;
          outbox_.push_back(rosserial::encodeFrame(*ch.init_topic, rosserial::encodeBool(true)));
          std::lock_guard counters_lock(counters_mutex_);
          ++counters_.inits_sent;
          message += "; init sent";
        }
      } else {
        std::lock_guard counters_lock(counters_mutex_);
        ++counters_.frames_before_init;
        result = RestampResult::kLearning;
      }
    }
    if (cam.initialised) {
      const auto number = static_cast<std::uint64_t>(frame - *cam.offset);
      const auto wait = std::chrono::steady_clock::now() + config_.restamp_wait;
      const BoardTime* found = nullptr;
      auto findTime = [&] {
        for (const BoardTime& t : ch.times)
          if (t.number == number) found = &t;
        return found != nullptr || !cam.initialised;
      };
      cameras_cv_.wait_until(lock, wait, findTime);
      if (!cam.initialised) {  // a new board session meanwhile
        result = RestampResult::kLearning;
      } else if (found) {
        stamp_ns = found->board_ns + config_.camera_offset_ns;
        cam.misses = 0;
        result = RestampResult::kRestamped;
        std::lock_guard counters_lock(counters_mutex_);
        ++counters_.frames_restamped;
      } else {
        result = RestampResult::kNoTime;
        if (++cam.misses >= config_.init_matches) {
          const std::size_t channel = cam.channel;  // the offset is lost: match again
          cam = CameraState();
          cam.channel = channel;
          message = "camera " + std::to_string(camera) + ": no board time for " +
                    std::to_string(config_.init_matches) +
                    " frames in a row, matching its frames to channel '" + ch.prefix + "' again";
        }
        std::lock_guard counters_lock(counters_mutex_);
        ++counters_.frames_unstamped;
      }
    }
    wake = !outbox_.empty();
  }
  if (wake) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(wake_fd_, &one, sizeof one);
  }
  if (!message.empty()) note(1, message);
  return result;
}

bool VersavisTriggerSource::cameraInitialised(std::size_t camera) const {
  std::lock_guard lock(cameras_mutex_);
  return camera < cameras_.size() && cameras_[camera].initialised;
}

std::optional<TriggerEvent> VersavisTriggerSource::next(std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  for (;;) {
    if (stopped_) return std::nullopt;
    if (!pending_error_.empty()) {
      const std::string e = std::move(pending_error_);
      pending_error_.clear();
      throw std::runtime_error(e);
    }
    while (!pending_.empty()) {
      const TriggerEvent e = pending_.front();
      const std::int64_t arrival = pending_arrival_.front();
      pending_.pop_front();
      pending_arrival_.pop_front();
      std::lock_guard lock(counters_mutex_);
      if (arrival < drop_before_ns_.load()) {
        ++counters_.triggers_before_start;  // the projector was not running yet
        continue;
      }
      ++counters_.triggers;
      return e;
    }
    // Messages for the board from the camera threads (init) and the reset.
    if (fd_ >= 0) {
      std::deque<std::vector<std::uint8_t>> out;
      {
        std::lock_guard lock(cameras_mutex_);
        out.swap(outbox_);
      }
      for (const auto& bytes : out) writeAll(bytes);
    }
    const auto now = Clock::now();
    if (fd_ < 0 && now >= next_reconnect_) {
      std::string ignored;
      if (tryOpen(&ignored))
        rebooting_ = false;
      else
        next_reconnect_ = now + (rebooting_ ? std::min(config_.reconnect_interval, kRebootRetry)
                                            : config_.reconnect_interval);
    }
    if (fd_ >= 0 && !trigger_topic_ && now >= next_negotiation_) sendTopicRequest();
    if (fd_ >= 0 && now - last_time_request_ >= config_.sync_timeout) {
      // rosserial_python: "Lost sync with device, restarting..." The board
      // stops publishing 11 s after its last time reply and waits for this.
      note(2, "no time request for " + ms(config_.sync_timeout) + ": requesting the topics again");
      last_time_request_ = now;
      count(&VersavisCounters::renegotiations);
      sendTopicRequest();
    }
    if (fd_ >= 0 && now - last_packet_ >= config_.watchdog) {
      bool report = false;
      {
        std::lock_guard lock(counters_mutex_);
        report = !counters_.silent;
        counters_.silent = true;
      }
      last_packet_ = now;  // report again only after another silent period... once
      if (report)
        throw std::runtime_error("VersaVIS " + config_.device + ": board silent for " +
                                 ms(config_.watchdog) + " (no packet; connected, " +
                                 std::to_string(counters().time_requests) +
                                 " time requests answered so far)");
    }
    if (now >= deadline) return std::nullopt;

    auto wake_at = deadline;
    if (fd_ < 0) wake_at = std::min(wake_at, next_reconnect_);
    if (fd_ >= 0 && !trigger_topic_) wake_at = std::min(wake_at, next_negotiation_);
    if (fd_ >= 0) {
      wake_at = std::min(wake_at, last_time_request_ + config_.sync_timeout);
      wake_at = std::min(wake_at, last_packet_ + config_.watchdog);
    }
    const auto wait_ms = std::max<std::int64_t>(
        0, std::chrono::ceil<std::chrono::milliseconds>(wake_at - now).count());
    pollfd fds[2] = {{wake_fd_, POLLIN, 0}, {fd_, POLLIN, 0}};
    const int n = poll(fds, fd_ >= 0 ? 2 : 1, static_cast<int>(wait_ms));
    if (n < 0 && errno != EINTR)
      throw std::runtime_error(std::string("VersaVIS: poll: ") + std::strerror(errno));
    if (n <= 0) continue;
    if (fds[0].revents) {
      if (stopped_) return std::nullopt;  // stop()
      std::uint64_t v;
      [[maybe_unused]] const ssize_t r = ::read(wake_fd_, &v, sizeof v);  // outgoing messages
      continue;
    }
    if (fd_ < 0 || fds[1].revents == 0) continue;
    std::uint8_t buf[512];
    const ssize_t got = ::read(fd_, buf, sizeof buf);
    if (got > 0) {
      parser_.feed(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(got)));
      const std::uint64_t before = counters().packets;
      while (auto frame = parser_.next()) handle(*frame);
      bool talking = false;
      {
        std::lock_guard lock(counters_mutex_);
        counters_.garbage_bytes = parser_.garbageBytes();
        counters_.checksum_errors = parser_.checksumErrors();
        if (counters_.silent && counters_.packets > before) {
          counters_.silent = false;
          talking = true;
        }
      }
      if (talking) note(1, "board talking again after a silence");
      continue;
    }
    if (got < 0 && (errno == EAGAIN || errno == EINTR)) continue;
    // Hang-up (read 0 or EIO): the board was unplugged or reset.
    const std::string why = got == 0 ? "end of file" : std::strerror(errno);
    closeDevice();
    next_reconnect_ = Clock::now() + config_.reconnect_interval;
    count(&VersavisCounters::disconnects);
    if (expect_hangup_) {
      // Our reset: the board reboots; reconnect quietly and soon (it is back
      // within about a second).
      expect_hangup_ = false;
      next_reconnect_ = Clock::now() + std::min(config_.reconnect_interval, kRebootRetry);
      rebooting_ = true;
      note(1, "board rebooting after the reset (" + why + "); reconnecting");
      continue;
    }
    pending_error_ = "VersaVIS " + config_.device + ": board disconnected (" + why +
                     "); reconnecting every " + ms(config_.reconnect_interval);
  }
}

void VersavisTriggerSource::stop() {
  stopped_ = true;
  const std::uint64_t one = 1;
  [[maybe_unused]] const ssize_t n = ::write(wake_fd_, &one, sizeof one);
}

VersavisCounters VersavisTriggerSource::counters() const {
  std::lock_guard lock(counters_mutex_);
  return counters_;
}

void VersavisTriggerSource::dropTriggersBefore(std::int64_t host_ns) { drop_before_ns_ = host_ns; }

void VersavisStartTapProjector::start(int count) {
  inner_->start(count);
  // Triggers the board sent before the projector was started (its clock can
  // be ~100 ms ahead of the host's, so their stamps alone cannot tell).
  source_->dropTriggersBefore(realtimeNs());
}

VersavisRestampCamera::VersavisRestampCamera(std::shared_ptr<Camera> camera,
                                             std::shared_ptr<VersavisTriggerSource> source,
                                             std::size_t index)
    : ForwardingCamera(std::move(camera)), source_(std::move(source)), index_(index) {
  if (index_ >= source_->cameraCount())
    throw std::invalid_argument("VersaVIS: camera '" + inner_->id() + "' (index " +
                                std::to_string(index_) + ") has no board camera channel");
}

std::optional<Frame> VersavisRestampCamera::grab(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    std::optional<Frame> frame = inner_->grab(std::max(left, std::chrono::milliseconds(0)));
    if (!frame) return frame;
    timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    const std::int64_t arrival = static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
    if (source_->restamp(index_, frame->frame_id, arrival, frame->stamp_ns) !=
        RestampResult::kNoTime)
      return frame;
    if (std::chrono::steady_clock::now() >= deadline) return std::nullopt;  // dropped, counted
  }
}

}  // namespace sl::drivers
