// ScanEngine without DDS: the health signal that feeds the systemd watchdog
// follows the pipeline threads, so a stuck device stops the pings.
#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"
#include "sl/drivers/sim.h"

using namespace std::chrono_literals;

namespace {

// A camera whose grab() hangs (ignores its timeout) once `hang` is set, until
// stop(): a driver stuck in a system call.
class HangingCamera : public sl::drivers::Camera {
 public:
  explicit HangingCamera(std::shared_ptr<sl::drivers::Camera> inner) : inner_(std::move(inner)) {}
  std::string id() const override { return inner_->id(); }
  int width() const override { return inner_->width(); }
  int height() const override { return inner_->height(); }
  void start() override { inner_->start(); }
  void stop() override {
    {
      std::lock_guard lock(mutex_);
      stopped_ = true;
    }
    cv_.notify_all();
    inner_->stop();
  }
  std::optional<sl::pipeline::Frame> grab(std::chrono::milliseconds timeout) override {
    if (hang) {
      std::unique_lock lock(mutex_);
      cv_.wait(lock, [&] { return stopped_; });
      return std::nullopt;
    }
    return inner_->grab(timeout);
  }
  std::atomic<bool> hang{false};

 private:
  std::shared_ptr<sl::drivers::Camera> inner_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stopped_ = false;
};

}  // namespace

TEST_CASE("the engine reports unhealthy while a device thread is stuck, and still shuts down") {
  const auto config = sl::daemon::loadConfig(std::string(SL_SOURCE_DIR) + "/config/sim.yaml");
  const auto sim = sl::drivers::SimulatedSensor::create(config.sim);
  auto camera = std::make_shared<HangingCamera>(sim->camera());
  sl::daemon::EngineDevices devices{{camera}, sim->projector(), sim->triggerSource()};
  std::atomic<int> clouds{0};
  {
    sl::daemon::ScanEngine engine(config, devices, [&](const sl::daemon::ScanResult&) { ++clouds; });
    std::this_thread::sleep_for(300ms);
    CHECK(engine.healthy());
    REQUIRE(engine.start("", 1).accepted());
    for (int i = 0; i < 100 && clouds == 0; ++i) std::this_thread::sleep_for(50ms);
    CHECK(clouds == 1);
    CHECK(engine.healthy());

    camera->hang = true;  // the next grab() never returns on its own
    const auto start = std::chrono::steady_clock::now();
    while (engine.healthy() && std::chrono::steady_clock::now() - start < 5s)
      std::this_thread::sleep_for(50ms);
    CHECK_FALSE(engine.healthy());
    // Unhealthy after the 2 s heartbeat limit (plus the grab timeout), not before.
    CHECK(std::chrono::steady_clock::now() - start > 1900ms);
  }  // destruction stops the camera, which releases the stuck grab()
  SUCCEED("engine destroyed");
}
