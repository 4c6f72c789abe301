// A fake VersaVIS board that behaves like the ethz-asl/versavis firmware of
// branch devel/sl_sensor (firmware/versavis/versavis.ino, Camera.cpp and the
// rosserial client it is built with), on the board side of a pseudo-terminal
// reached through a device symlink (like udev's /dev/versavis):
//
// - rosserial session: answers a topic request (topic 0) with its
//   subscribers' TopicInfos (/versavis/reset = id 100, then one
//   "<camera>init" per camera channel, topic 1) and its publishers' (one
//   "<channel>image_time" per channel from id 125, topic 0), then asks for
//   the time; asks again every sync_period while configured; 11 s (x time
//   scale) after the last time reply it drops the session (publishes nothing,
//   asks for nothing) until the next topic request; TX_STOP ends it too.
// - setup(): every camera channel waits for std_msgs/Bool true on its
//   "<prefix>init" topic; meanwhile the board pulses each waiting camera at
//   1 Hz (init_pulse_period) and publishes its image_time, and there are no
//   projector trigger times at all. Once every camera is initialised the
//   timers start together: projector channel at projector_rate_hz, cameras
//   at camera_rate_hz, each trigger published with its board time and number.
// - clock: the board's time is the host's plus an offset that a filter
//   steers with each time reply (offset gain 0.105, skew gain 0.007 per
//   reply, hard-coded start offset +100 ms and a skew 3 ms/s off), which
//   reproduces the model of the firmware's filter in issue 19: board minus
//   host about +100 ms at start, +47 ms at 30 s, +8 ms at 60 s, a few ms
//   after 2 min; residuals above 0.5 s are ignored. All periods of the
//   filter and of rosserial's sync (2.5 s, 11 s) are divided by time_scale
//   so a test can see a minute of convergence in seconds.
// - /versavis/reset (any Bool): the board reboots (NVIC_SystemReset): it
//   hangs up, comes back as a new pseudo-terminal after reboot_delay, and
//   starts again from setup() (handshake, filter at +100 ms).
// - camera triggers call on_trigger(channel, board number, host time) so a
//   fake camera can deliver a frame for it.
// - it can send rosserial_msgs/Log messages (log()), and be made silent.
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "sl/drivers/versavis.h"

namespace sl::test {

namespace rs = drivers::rosserial;

struct FakeVersavisOptions {
  std::string projector_prefix = "/versavis/projector/";
  std::vector<std::string> camera_prefixes = {"/versavis/cam1/"};
  double projector_rate_hz = 5;
  double camera_rate_hz = 30;
  double time_scale = 1;  // divides rosserial's sync periods and the filter's time
  std::chrono::milliseconds init_pulse_period{1000};
  std::chrono::milliseconds setup_delay{1000};  // the firmware's delay(1000) before nh.initNode()
  std::chrono::milliseconds reboot_delay{500};  // reset until the device reappears
  double start_offset_ms = 100;                 // board minus host before the first time reply
  double start_skew_ms_per_s = 3;          // board clock rate error before the filter corrects it
  std::string md5 = rs::kTimeNumberedMd5;  // of the image_time topics
  std::string bool_md5 = rs::kBoolMd5;
};

class FakeVersavisBoard {
 public:
  // (channel: 0 = projector, 1.. = cameras; board number; host time ns)
  using TriggerCallback = std::function<void(int, std::uint64_t, std::int64_t)>;

  explicit FakeVersavisBoard(FakeVersavisOptions options, TriggerCallback on_trigger = {})
      : o_(std::move(options)), on_trigger_(std::move(on_trigger)) {
    char tmpl[] = "/tmp/sl_fake_versavis_XXXXXX";
    if (!mkdtemp(tmpl)) throw std::runtime_error("mkdtemp failed");
    dir_ = tmpl;
    boot();
    thread_ = std::thread([this] { run(); });
  }
  ~FakeVersavisBoard() {
    running_ = false;
    thread_.join();
    if (master_ >= 0) ::close(master_);
    std::filesystem::remove_all(dir_);
  }
  FakeVersavisBoard(const FakeVersavisBoard&) = delete;
  FakeVersavisBoard& operator=(const FakeVersavisBoard&) = delete;

  std::string devicePath() const { return (dir_ / "versavis").string(); }

  // Board minus host clock now, ns.
  std::int64_t offsetNs() const {
    std::lock_guard lock(mutex_);
    return offsetAtLocked(hostNs());
  }
  bool configured() const { return configured_; }
  // Past the setup delay of the current boot (reads the port).
  bool ready() const { return Clock::now() >= ready_at_.load(); }
  bool allInitialised() const { return initialised_; }
  int boots() const { return boots_; }
  int timeReplies() const { return time_replies_; }
  int resets() const { return resets_; }
  int txStops() const { return tx_stops_; }
  std::uint64_t projectorTriggers() const { return projector_number_; }
  // Time request answers are ignored while false (the host looks dead).
  void answerTimeRequests(bool on) { ignore_replies_ = !on; }
  void log(std::uint8_t level, const std::string& text) {
    std::lock_guard lock(mutex_);
    pending_logs_.push_back({level, text});
  }
  // Publish on a topic id that was never negotiated (as after a reboot the
  // host did not see).
  void publishUnknownTopic() { unknown_ = true; }

  static std::int64_t hostNs() {
    timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
  }

 private:
  using Clock = std::chrono::steady_clock;
  static constexpr std::uint16_t kResetId = 100;
  static constexpr std::uint16_t kFirstPublisher = 125;

  void boot() {
    if (master_ >= 0) ::close(master_);
    master_ = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
    if (master_ < 0 || grantpt(master_) != 0 || unlockpt(master_) != 0)
      throw std::runtime_error("no pseudo-terminal");
    const auto link = dir_ / "versavis";
    const auto tmp = dir_ / "versavis.new";
    std::filesystem::remove(tmp);
    std::filesystem::create_symlink(ptsname(master_), tmp);
    std::filesystem::rename(tmp, link);
    parser_.clear();
    configured_ = false;
    initialised_ = false;
    cam_init_.assign(o_.camera_prefixes.size(), false);
    numbers_.assign(o_.camera_prefixes.size() + 1, 0);
    projector_number_ = 0;
    {
      std::lock_guard lock(mutex_);
      const std::int64_t now = hostNs();
      filter_at_ns_ = now;
      error_ns_ = o_.start_offset_ms * 1e6;
      skew_ns_per_s_ = o_.start_skew_ms_per_s * 1e6 * o_.time_scale;
    }
    ready_at_ = Clock::now() + o_.setup_delay;
    ++boots_;
  }

  // Board minus host at host time t (the filter's state drifts with the skew).
  std::int64_t offsetAtLocked(std::int64_t t) const {
    return static_cast<std::int64_t>(error_ns_ + skew_ns_per_s_ * (t - filter_at_ns_) * 1e-9);
  }
  std::int64_t boardNs(std::int64_t host) const {
    std::lock_guard lock(mutex_);
    return host + offsetAtLocked(host);
  }

  void send(std::uint16_t topic, const std::vector<std::uint8_t>& message) {
    const auto bytes = rs::encodeFrame(topic, message);
    std::size_t done = 0;
    for (int tries = 0; done < bytes.size() && tries < 1000; ++tries) {
      const ssize_t n = ::write(master_, bytes.data() + done, bytes.size() - done);
      if (n > 0)
        done += static_cast<std::size_t>(n);
      else
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

  void publishTime(int channel, std::int64_t host) {
    const std::uint64_t number = ++numbers_[static_cast<std::size_t>(channel)];
    if (channel == 0) projector_number_ = number;
    const std::int64_t b = boardNs(host);
    if (configured_)  // rosserial drops publications of an unconfigured node
      send(static_cast<std::uint16_t>(kFirstPublisher + channel),
           rs::encodeTimeNumbered({static_cast<std::uint32_t>(b / 1000000000),
                                   static_cast<std::uint32_t>(b % 1000000000), number}));
    if (on_trigger_) on_trigger_(channel, number, host);
  }

  void negotiate() {
    std::uint16_t sub = kResetId;
    send(rs::kTopicSubscriber,
         rs::encodeTopicInfo({sub++, "/versavis/reset", rs::kBoolType, o_.bool_md5, 512}));
    for (const auto& p : o_.camera_prefixes)
      send(rs::kTopicSubscriber,
           rs::encodeTopicInfo({sub++, p + "init", rs::kBoolType, o_.bool_md5, 512}));
    send(rs::kTopicPublisher,
         rs::encodeTopicInfo({kFirstPublisher, o_.projector_prefix + "image_time",
                              rs::kTimeNumberedType, o_.md5, 512}));
    for (std::size_t i = 0; i < o_.camera_prefixes.size(); ++i)
      send(rs::kTopicPublisher,
           rs::encodeTopicInfo({static_cast<std::uint16_t>(kFirstPublisher + 1 + i),
                                o_.camera_prefixes[i] + "image_time", rs::kTimeNumberedType, o_.md5,
                                512}));
    configured_ = true;
    requestTime();
    last_reply_ = Clock::now();
  }

  void requestTime() {
    send(rs::kTopicTime, {});
    last_request_ = Clock::now();
  }

  void onTimeReply(std::int64_t host_time) {
    if (ignore_replies_) return;
    ++time_replies_;
    last_reply_ = Clock::now();
    std::lock_guard lock(mutex_);
    const std::int64_t now = hostNs();
    // The state at now, then one filter update on the residual host - board.
    error_ns_ = static_cast<double>(offsetAtLocked(now));
    filter_at_ns_ = now;
    const double residual = static_cast<double>(host_time - now) - error_ns_;
    if (std::abs(residual) > 0.5e9) return;  // the firmware ignores large residuals
    const double period_s = 2.5 / o_.time_scale;
    error_ns_ += 0.105 * residual;
    skew_ns_per_s_ += 0.007 * residual / period_s;
  }

  void handle(const rs::Frame& f) {
    if (f.topic_id == rs::kTopicPublisher) {
      negotiate();
    } else if (f.topic_id == rs::kTopicTime) {
      if (auto t = rs::decodeTime(f.message)) onTimeReply(*t);
    } else if (f.topic_id == rs::kTopicTxStop) {
      ++tx_stops_;
      configured_ = false;
    } else if (f.topic_id == kResetId) {
      ++resets_;
      reboot_pending_ = true;
    } else if (f.topic_id > kResetId &&
               f.topic_id <= kResetId + static_cast<std::uint16_t>(o_.camera_prefixes.size())) {
      const auto v = rs::decodeBool(f.message);
      if (v) cam_init_[f.topic_id - kResetId - 1] = *v;
    }
  }

  void run() {
    const auto sync_period = std::chrono::duration<double>(2.5 / o_.time_scale);
    const auto sync_timeout = std::chrono::duration<double>(11.0 / o_.time_scale);
    Clock::time_point next_pulse{}, timers_at{};
    std::uint64_t projector_k = 0, camera_k = 0;
    bool timers = false;
    while (running_) {
      const auto now = Clock::now();
      if (reboot_pending_) {
        reboot_pending_ = false;
        ::close(master_);  // hang-up
        master_ = -1;
        std::this_thread::sleep_for(o_.reboot_delay);
        boot();
        timers = false;
        continue;
      }
      if (now < ready_at_.load()) {  // setup's delay(1000): host bytes wait in the USB buffer
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        continue;
      }
      if (configured_) {
        if (now - last_request_ >= sync_period) requestTime();
        if (now - last_reply_ >= sync_timeout) configured_ = false;  // "lost sync"
        std::vector<rs::LogMessage> logs;
        {
          std::lock_guard lock(mutex_);
          logs.swap(pending_logs_);
        }
        for (const auto& l : logs) send(rs::kTopicLog, rs::encodeLog(l));
        if (unknown_.exchange(false)) send(180, rs::encodeTimeNumbered({0, 0, 1}));
      }
      if (!initialised_) {
        bool all = true;
        for (bool b : cam_init_) all = all && b;
        if (all) {
          initialised_ = true;
          timers = true;
          timers_at = now;
          projector_k = camera_k = 0;
        } else if (now >= next_pulse) {  // Camera::initialize(): one pulse per second
          next_pulse = now + o_.init_pulse_period;
          const std::int64_t host = hostNs();
          for (std::size_t i = 0; i < cam_init_.size(); ++i)
            if (!cam_init_[i]) publishTime(static_cast<int>(i + 1), host);
        }
      }
      // spinOnce(): host bytes (after this iteration's camera pulses, as in
      // the firmware's setup loop: the first pulse goes out unconfigured).
      pollfd p{master_, POLLIN, 0};
      if (poll(&p, 1, 1) > 0 && (p.revents & POLLIN)) {
        std::uint8_t buf[512];
        const ssize_t n = ::read(master_, buf, sizeof buf);
        if (n > 0) parser_.feed(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n)));
        while (auto f = parser_.next()) handle(*f);
      }
      if (timers) {
        // Hardware timers: a trigger happens at its scheduled time, however
        // late this loop gets to publish it (host time of the schedule).
        auto hostAt = [&](Clock::time_point at) {
          return hostNs() -
                 std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - at).count();
        };
        // Trigger k of a timer started at timers_at: exact multiples of the period.
        auto due = [&](double rate_hz, std::uint64_t k) {
          return timers_at + std::chrono::duration_cast<Clock::duration>(
                                 std::chrono::duration<double>(static_cast<double>(k) / rate_hz));
        };
        while (due(o_.projector_rate_hz, projector_k) <= Clock::now())
          publishTime(0, hostAt(due(o_.projector_rate_hz, projector_k++)));
        while (due(o_.camera_rate_hz, camera_k) <= Clock::now()) {
          const std::int64_t host = hostAt(due(o_.camera_rate_hz, camera_k++));
          for (std::size_t i = 0; i < cam_init_.size(); ++i)
            publishTime(static_cast<int>(i + 1), host);
        }
      }
    }
  }

  const FakeVersavisOptions o_;
  const TriggerCallback on_trigger_;
  std::filesystem::path dir_;
  int master_ = -1;
  rs::FrameParser parser_;
  std::atomic<bool> running_{true}, configured_{false}, initialised_{false};
  std::atomic<bool> ignore_replies_{false}, reboot_pending_{false}, unknown_{false};
  std::atomic<int> boots_{0}, time_replies_{0}, resets_{0}, tx_stops_{0};
  std::atomic<std::uint64_t> projector_number_{0};
  std::vector<bool> cam_init_;
  std::vector<std::uint64_t> numbers_;
  std::atomic<Clock::time_point> ready_at_{};
  Clock::time_point last_request_{}, last_reply_{};
  mutable std::mutex mutex_;
  double error_ns_ = 0, skew_ns_per_s_ = 0;   // guarded by mutex_
  std::int64_t filter_at_ns_ = 0;             // guarded by mutex_
  std::vector<rs::LogMessage> pending_logs_;  // guarded by mutex_
  std::thread thread_;
};

}  // namespace sl::test
