// Test helper: runs sl_sensord as a child process with a config derived from
// config/sim.yaml (unique namespace, loopback-only DDS), and stops it with
// SIGTERM. Every wait is bounded: a hung daemon fails the test and is killed.
#pragma once

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "sl/client/client.h"
#include "sl/daemon/config.h"
#include "support/time_scale.h"

extern char** environ;

namespace sl::test {

inline std::string sourcePath(const std::string& relative) {
  return std::string(SL_SOURCE_DIR) + "/" + relative;
}

// Points Cyclone DDS at the loopback-only configuration (call before any
// participant exists; children inherit it), with the participants' lease
// scaled in sanitizer builds (scaledDdsLeaseXml).
inline void useLoopbackDds() {
  setenv("CYCLONEDDS_URI",
         ("file://" + sourcePath("config/cyclonedds-loopback.xml") + scaledDdsLeaseXml()).c_str(),
         1);
}

// A namespace no other test process uses.
inline std::string uniqueNamespace(const std::string& prefix) {
  return prefix + "_" + std::to_string(::getpid()) + "_" +
         std::to_string(std::chrono::steady_clock::now().time_since_epoch().count() % 100000);
}

inline std::int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// config/sim.yaml with dds.namespace set to `ns`, for further edits; the
// simulated camera at scaledCameraFps (30 Hz outside sanitizer builds) and
// the grouping's wait for late frames stretched by the same factor.
inline YAML::Node simConfig(const std::string& ns) {
  YAML::Node root = YAML::LoadFile(sourcePath("config/sim.yaml"));
  root["dds"]["namespace"] = ns;
  root["sim"]["camera_fps"] = scaledCameraFps(root["sim"]["camera_fps"].as<double>());
  root["synchroniser"]["max_age_s"] = root["synchroniser"]["max_age_s"].as<double>() * kTimeScale;
  // The health check's "no scan published" bound (stall_timeout_s plus a
  // sequence), likewise: under TSan a 3+3 set takes longer than 2 s to process.
  root["runtime"]["stall_timeout_s"] = sl::daemon::RuntimeConfig{}.stall_timeout_s * kTimeScale;
  return root;
}

// Writes `root` to /tmp/sl_test_<name>.yaml and returns the path.
inline std::string writeConfigFile(const YAML::Node& root, const std::string& name) {
  const std::string path = "/tmp/sl_test_" + name + ".yaml";
  std::ofstream(path) << root;
  return path;
}

// config/sim.yaml with dds.namespace replaced (and projector maps published
// if asked), written to a file; returns its path.
inline std::string writeTestConfig(const std::string& ns, bool publish_maps = false) {
  YAML::Node root = simConfig(ns);
  root["dds"]["publish_projector_maps"] = publish_maps;
  return writeConfigFile(root, ns);
}

// A child process running `args` (args[0]: the binary's path) in the test's
// environment; killed if still running when destroyed.
class ChildProcess {
 public:
  explicit ChildProcess(std::vector<std::string> args) {
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    if (posix_spawn(&pid_, args.at(0).c_str(), nullptr, nullptr, argv.data(), environ) != 0)
      pid_ = -1;
  }
  ~ChildProcess() {
    if (pid_ > 0 && !exit_status_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;
  bool started() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }
  void signal(int number) const { ::kill(pid_, number); }

  // Waits up to `timeout` (not scaled) for the process to end by itself;
  // its exit status (128 + signal if killed), or nullopt while it runs.
  std::optional<int> waitExit(std::chrono::milliseconds timeout) {
    if (exit_status_) return exit_status_;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    do {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        return exit_status_;
      }
      if (timeout.count() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    } while (std::chrono::steady_clock::now() < deadline);
    return std::nullopt;
  }

  // Sends SIGTERM and waits up to `timeout` (x kTimeScale in sanitizer
  // builds); returns the exit status, or nullopt if the process had to be
  // killed.
  std::optional<int> terminate(std::chrono::milliseconds timeout) {
    ::kill(pid_, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + scaledBound(timeout);
    while (std::chrono::steady_clock::now() < deadline) {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        return exit_status_;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return std::nullopt;
  }

 private:
  pid_t pid_ = -1;
  std::optional<int> exit_status_;
};

// sl_sensord --config config_path.
class DaemonProcess : public ChildProcess {
 public:
  explicit DaemonProcess(const std::string& config_path)
      : ChildProcess({std::string(SL_BINARY_DIR) + "/daemon/sl_sensord", "--config", config_path}) {}
};

// The first status satisfying `done`, polling for at most `timeout` (the
// last one read if none did).
template <typename Done>
std::optional<sl::client::StatusInfo> statusWhen(sl::client::SensorClient& client, Done done,
                                                 std::chrono::milliseconds timeout) {
  std::optional<sl::client::StatusInfo> s;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    s = client.status(std::chrono::seconds(1));
    if (s && done(*s)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return s;
}

}  // namespace sl::test
