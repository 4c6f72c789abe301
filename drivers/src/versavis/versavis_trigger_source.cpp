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

}  // namespace

VersavisTriggerSource::VersavisTriggerSource(VersavisConfig config) : config_(std::move(config)) {
  if (config_.baud <= 0) throw std::invalid_argument("VersaVIS: baud must be > 0");
  if (config_.triggers_per_sequence < 1)
    throw std::invalid_argument("VersaVIS: triggers_per_sequence must be >= 1");
  wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw std::runtime_error(std::string("eventfd: ") + std::strerror(errno));
  std::string error;
  if (!tryOpen(&error)) {
    close(wake_fd_);
    throw std::runtime_error(error);
  }
}

VersavisTriggerSource::~VersavisTriggerSource() {
  closeDevice();
  if (wake_fd_ >= 0) close(wake_fd_);
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
  trigger_topic_.reset();
  first_number_.reset();
  {
    std::lock_guard lock(counters_mutex_);
    ++counters_.connects;
  }
  sendTopicRequest();
  return true;
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
  std::lock_guard lock(counters_mutex_);
  ++counters_.topic_requests;
}

void VersavisTriggerSource::handle(const rosserial::Frame& frame) {
  auto count = [&](std::uint64_t VersavisCounters::*field) {
    std::lock_guard lock(counters_mutex_);
    ++(counters_.*field);
  };
  count(&VersavisCounters::packets);
  if (frame.topic_id == rosserial::kTopicTime) {
    // A time request (empty) from the board: answer with the host clock.
    writeAll(rosserial::encodeFrame(rosserial::kTopicTime, rosserial::encodeTime(realtimeNs())));
    count(&VersavisCounters::time_requests);
    return;
  }
  if (frame.topic_id == rosserial::kTopicPublisher) {
    const auto info = rosserial::decodeTopicInfo(frame.message);
    if (!info) {
      count(&VersavisCounters::malformed);
      return;
    }
    if (info->topic_name != config_.topic) return;
    if (info->message_type != config_.message_type) {
      trigger_topic_.reset();
      throw std::runtime_error("VersaVIS " + config_.device + ": topic '" + config_.topic +
                               "' has type '" + info->message_type + "', expected '" +
                               config_.message_type + "'");
    }
    trigger_topic_ = info->topic_id;
    return;
  }
  if (!trigger_topic_ || frame.topic_id != *trigger_topic_) return;  // other sensors, logs
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
    if (!pending_.empty()) {
      const TriggerEvent e = pending_.front();
      pending_.pop_front();
      std::lock_guard lock(counters_mutex_);
      ++counters_.triggers;
      return e;
    }
    const auto now = Clock::now();
    if (fd_ < 0 && now >= next_reconnect_) {
      std::string ignored;
      if (!tryOpen(&ignored)) next_reconnect_ = now + config_.reconnect_interval;
    }
    if (fd_ >= 0 && !trigger_topic_ && now >= next_negotiation_) sendTopicRequest();
    if (now >= deadline) return std::nullopt;

    auto wake_at = deadline;
    if (fd_ < 0) wake_at = std::min(wake_at, next_reconnect_);
    if (fd_ >= 0 && !trigger_topic_) wake_at = std::min(wake_at, next_negotiation_);
    const auto wait_ms = std::max<std::int64_t>(
        0, std::chrono::ceil<std::chrono::milliseconds>(wake_at - now).count());
    pollfd fds[2] = {{wake_fd_, POLLIN, 0}, {fd_, POLLIN, 0}};
    const int n = poll(fds, fd_ >= 0 ? 2 : 1, static_cast<int>(wait_ms));
    if (n < 0 && errno != EINTR)
      throw std::runtime_error(std::string("VersaVIS: poll: ") + std::strerror(errno));
    if (n <= 0) continue;
    if (fds[0].revents) return std::nullopt;  // stop()
    if (fd_ < 0 || fds[1].revents == 0) continue;
    std::uint8_t buf[512];
    const ssize_t got = ::read(fd_, buf, sizeof buf);
    if (got > 0) {
      parser_.feed(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(got)));
      while (auto frame = parser_.next()) handle(*frame);
      std::lock_guard lock(counters_mutex_);
      counters_.garbage_bytes = parser_.garbageBytes();
      counters_.checksum_errors = parser_.checksumErrors();
      continue;
    }
    if (got < 0 && (errno == EAGAIN || errno == EINTR)) continue;
    // Hang-up (read 0 or EIO): the board was unplugged or reset.
    const std::string why = got == 0 ? "end of file" : std::strerror(errno);
    closeDevice();
    next_reconnect_ = Clock::now() + config_.reconnect_interval;
    {
      std::lock_guard lock(counters_mutex_);
      ++counters_.disconnects;
    }
    pending_error_ = "VersaVIS " + config_.device + ": board disconnected (" + why +
                     "); reconnecting every " + std::to_string(config_.reconnect_interval.count()) +
                     " ms";
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

}  // namespace sl::drivers
