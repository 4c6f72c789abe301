// Bases of device decorators: each forwards every call to the device it
// wraps, so a decorator overrides only what it changes (restamping frames,
// tapping stamps or starts, injecting faults in tests). Thread-safety as the
// wrapped device.
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "sl/drivers/camera.h"
#include "sl/drivers/projector.h"

namespace sl::drivers {

class ForwardingCamera : public Camera {
 public:
  explicit ForwardingCamera(std::shared_ptr<Camera> inner) : inner_(std::move(inner)) {}
  std::string id() const override { return inner_->id(); }
  int width() const override { return inner_->width(); }
  int height() const override { return inner_->height(); }
  void start() override { inner_->start(); }
  void stop() override { inner_->stop(); }
  std::optional<Frame> grab(std::chrono::milliseconds timeout) override { return inner_->grab(timeout); }
  bool hasSoftwareTrigger() const override { return inner_->hasSoftwareTrigger(); }
  void triggerSoftware() override { inner_->triggerSoftware(); }

 protected:
  const std::shared_ptr<Camera> inner_;
};

class ForwardingProjector : public Projector {
 public:
  explicit ForwardingProjector(std::shared_ptr<Projector> inner) : inner_(std::move(inner)) {}
  std::string id() const override { return inner_->id(); }
  std::vector<ProjectorSequence> sequences() const override { return inner_->sequences(); }
  void select(const std::string& name) override { inner_->select(name); }
  void start(int count) override { inner_->start(count); }
  void stop() override { inner_->stop(); }
  bool canProjectSingle() const override { return inner_->canProjectSingle(); }
  void projectSingle(int index) override { inner_->projectSingle(index); }

 protected:
  const std::shared_ptr<Projector> inner_;
};

}  // namespace sl::drivers
