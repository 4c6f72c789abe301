#include "aravis_devices.h"

#include <atomic>
#include <stdexcept>
#include <thread>

#include "sl/daemon/log.h"
#include "sl/drivers/aravis_camera.h"
#include "sl/drivers/aravis_fake_camera.h"
#include "sl/drivers/sim.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::client::TriggerMode;

namespace {

using namespace std::chrono_literals;

std::shared_ptr<drivers::AravisCamera> openCamera(const drivers::AravisCameraConfig& c) {
  auto camera = drivers::AravisCamera::open(c);
  logInfo("camera '" + c.name + "': opened " + camera->deviceId() + ", " +
          std::to_string(camera->width()) + "x" + std::to_string(camera->height()) + " " +
          c.pixel_format);
  for (const std::string& note : camera->notes()) logInfo("camera '" + c.name + "': " + note);
  return camera;
}

// The fake GigE sensor: a thread moves every frame of the simulated camera
// (rendered on the simulated trigger schedule) into the fake GigE camera and
// triggers it, as the trigger line would. Destruction stops and joins the
// thread before the fake camera and the simulator go.
class FakeGigeSensor {
 public:
  FakeGigeSensor(std::shared_ptr<drivers::SimulatedSensor> sim,
                 std::unique_ptr<drivers::FakeGigeCamera> fake)
      : sim_(std::move(sim)), fake_(std::move(fake)), source_(sim_->camera()) {
    source_->start();
    thread_ = std::thread([this] { feed(); });
  }
  ~FakeGigeSensor() {
    running_ = false;
    source_->stop();
    thread_.join();
  }
  FakeGigeSensor(const FakeGigeSensor&) = delete;
  FakeGigeSensor& operator=(const FakeGigeSensor&) = delete;

  drivers::SimulatedSensor& sim() { return *sim_; }

 private:
  void feed() {
    while (running_) {
      try {
        auto frame = source_->grab(100ms);
        if (frame) fake_->push(std::move(frame->image), static_cast<std::uint64_t>(frame->stamp_ns));
      } catch (const std::exception& e) {
        logWarning(std::string("fake GigE sensor: ") + e.what());
        std::this_thread::sleep_for(100ms);
      }
    }
  }

  const std::shared_ptr<drivers::SimulatedSensor> sim_;
  const std::unique_ptr<drivers::FakeGigeCamera> fake_;
  const std::shared_ptr<drivers::Camera> source_;
  std::atomic<bool> running_{true};
  std::thread thread_;  // last: starts after everything it uses
};

// The fake GigE camera as the engine sees it: the AravisCamera, whose
// software trigger is passed to the simulated camera. That renders the
// pattern the simulated projector holds, and the feeder sends the image
// through the fake camera with its in-process trigger, as for the schedule's
// frames. Thread-safety as AravisCamera.
class FakeGigeSoftwareTriggerCamera final : public drivers::Camera {
 public:
  FakeGigeSoftwareTriggerCamera(std::shared_ptr<drivers::Camera> camera,
                                std::shared_ptr<drivers::Camera> simulated)
      : camera_(std::move(camera)), simulated_(std::move(simulated)) {}
  std::string id() const override { return camera_->id(); }
  int width() const override { return camera_->width(); }
  int height() const override { return camera_->height(); }
  void start() override { camera_->start(); }
  void stop() override { camera_->stop(); }
  std::optional<drivers::Frame> grab(std::chrono::milliseconds timeout) override {
    return camera_->grab(timeout);
  }
  bool hasSoftwareTrigger() const override { return simulated_->hasSoftwareTrigger(); }
  void triggerSoftware() override { simulated_->triggerSoftware(); }

 private:
  const std::shared_ptr<drivers::Camera> camera_;
  const std::shared_ptr<drivers::Camera> simulated_;
};

}  // namespace

void appendAravisCameras(const DaemonConfig& config, EngineDevices& devices) {
  for (const auto& c : config.aravis.cameras) {
    devices.cameras.push_back(openCamera(c));
    // Its trigger source is fixed at open: only the daemon triggers it.
    const bool software_only = c.trigger.mode == drivers::AravisTriggerConfig::Mode::kSoftware;
    if (config.sensor == SensorKind::kHardware && software_only &&
        config.runtime.trigger == TriggerMode::kHardware)
      logWarning("camera '" + c.name +
                 "': trigger mode software, but runtime.trigger is hardware: "
                 "requests without 'trigger software' will get no frames from this camera");
  }
}

EngineDevices openFakeGige(const DaemonConfig& config, std::shared_ptr<void>& keep_alive) {
  std::shared_ptr<drivers::SimulatedSensor> sim;
  try {
    sim = drivers::SimulatedSensor::create(config.sim);
  } catch (const std::exception& e) {
    throw std::runtime_error(config.source_path + ": simulated sensor: " + e.what());
  }
  auto fake = std::make_unique<drivers::FakeGigeCamera>(config.aravis.fake);
  logInfo("fake GigE camera " + fake->deviceId() + " listening on " +
          config.aravis.fake.interface_address);
  auto sensor = std::make_shared<FakeGigeSensor>(sim, std::move(fake));
  keep_alive = sensor;
  EngineDevices devices;
  appendAravisCameras(config, devices);
  devices.cameras.front() =
      std::make_shared<FakeGigeSoftwareTriggerCamera>(devices.cameras.front(), sim->camera());
  devices.projector = sim->projector();
  devices.trigger = sim->triggerSource();
  return devices;
}

}  // namespace sl::daemon
