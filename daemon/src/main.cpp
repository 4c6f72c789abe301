// sl_sensord: the structured-light sensor daemon. Composition root: parse
// arguments, load the config, open the devices, run until SIGINT/SIGTERM.
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <optional>
#include <algorithm>
#include <cstdio>
#include <string>
#include <thread>

#include "sl/daemon/config.h"
#include "sl/dds/dds.h"
#include "sl/daemon/dds_bridge.h"
#include "sl/dds/environment.h"
#include "sl/daemon/devices.h"
#include "sl/daemon/log.h"
#include "sl/daemon/scan_engine.h"
#include "sl/daemon/systemd_notify.h"
#include "instance_lock.h"
#include "other_daemon.h"
#include "config_reload.h"
#include "reload_worker.h"

namespace {

std::atomic<bool> startup_done{false};
std::atomic<bool> reload_asked_in_startup{false};  // SIGHUP before the main loop
std::thread startup_watch;  // watchStartup() until the daemon is ready

void endStartupWatch() {
  startup_done = true;
  if (startup_watch.joinable()) startup_watch.join();
}

constexpr const char* kUsage =
    "usage: sl_sensord --config FILE\n"
    "  Runs the structured-light sensor daemon in the foreground.\n"
    "  --config FILE   YAML configuration (e.g. config/sim.yaml)\n"
    "  --help          this text\n"
    "Topics and requests: see README.md. Stops cleanly on SIGINT/SIGTERM;\n"
    "SIGHUP reloads the run-time settings (decoder, triangulator, motion_compensation,\n"
    "dds.status_period_s) from FILE.\n";

// SIGHUP: re-reads the config file and applies what can change at run time
// (decoder, triangulator, motion_compensation, dds.status_period_s). A file
// that does not load, or that changes anything else, is rejected as a whole
// with a message; the daemon keeps running as it was. The file is loaded by
// a ReloadWorker (its own thread, the bounded reader, kReloadDeadline): the
// main loop keeps taking signals meanwhile, and a load past the deadline is
// refused. Every refusal is in the status (last_error, source "reload").
constexpr std::chrono::milliseconds kReloadDeadline{5000};

void beginReload(const std::string& path, sl::daemon::ReloadWorker& reloads,
                 sl::daemon::ScanEngine& engine) {
  using namespace sl::daemon;
  using ::sl::files::ConfigError;
  using ::sl::dds::TopicNames;
  using ::sl::dds::currentDdsHost;
  using ::sl::dds::ddsEnvironmentProblems;
  using ::sl::dds::readDdsRequirements;
  const std::string busy = reloads.begin(path);
  if (busy.empty()) {
    systemdNotify("RELOADING=1");
    return;
  }
  const std::string message = "config reload refused: " + busy + "; nothing was applied";
  logWarning(message);
  engine.reportError(message, "reload");
}

void finishReload(sl::daemon::ReloadWorker::Outcome outcome, const sl::daemon::DaemonConfig& running,
                  sl::daemon::ScanEngine& engine, sl::daemon::DdsBridge& bridge) {
  using namespace sl::daemon;
  using ::sl::files::ConfigError;
  using ::sl::dds::TopicNames;
  using ::sl::dds::currentDdsHost;
  using ::sl::dds::ddsEnvironmentProblems;
  using ::sl::dds::readDdsRequirements;
  using Kind = ReloadWorker::Outcome::Kind;
  const std::string& path = outcome.path;
  if (outcome.kind == Kind::kTimedOut) {
    const std::string message =
        "config reload refused: loading " + path + " did not finish within " +
        std::to_string(kReloadDeadline.count() / 1000) +
        " s (a file that blocks, e.g. a FIFO, or a file system that does not answer); nothing "
        "was applied";
    logWarning(message);
    engine.reportError(message, "reload");
  } else if (outcome.kind == Kind::kFailed) {
    logWarning("config reload failed, keeping the running config: " + outcome.error);
    engine.reportError("config reload failed: " + outcome.error, "reload");
  } else {
    try {
      const DaemonConfig& loaded = *outcome.config;
      const std::vector<std::string> changed = keysNeedingRestart(running, loaded);
      if (!changed.empty()) {
        std::string keys;
        for (const auto& k : changed) keys += (keys.empty() ? "'" : ", '") + k + "'";
        const std::string message = "config reload rejected: " + keys +
                                    " changed, which needs a restart; nothing was applied";
        logWarning(message);
        engine.reportError(message, "reload");
      } else {
        engine.applyRuntimeSettings(loaded);
        engine.clearError("reload");  // an earlier reload's error no longer holds
        bridge.setStatusPeriod(loaded.dds.status_period_s);
        logInfo("config reloaded from " + path + " (" + reloadableKeysText() + ")");
      }
    } catch (const std::exception& e) {
      logWarning(std::string("config reload failed, keeping the running config: ") + e.what());
      engine.reportError(std::string("config reload failed: ") + e.what(), "reload");
    }
  }
  systemdNotify("READY=1");
}

// One warning line per thing the DDS configuration asks for and the host
// cannot give (socket buffers above the kernel's limits, shared memory
// without RouDi): the daemon then still runs, slower, but never silently.
void checkDdsEnvironment() {
  using namespace sl::daemon;
  using ::sl::files::ConfigError;
  using ::sl::dds::TopicNames;
  using ::sl::dds::currentDdsHost;
  using ::sl::dds::ddsEnvironmentProblems;
  using ::sl::dds::readDdsRequirements;
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri == nullptr || *uri == '\0') return;
  try {
    for (const std::string& line : ddsEnvironmentProblems(readDdsRequirements(uri), currentDdsHost()))
      logWarning(line);
  } catch (const std::exception& e) {
    logWarning(std::string("DDS environment not checked: ") + e.what());
  }
}
// How long start-up looks for another daemon on the same domain and
// namespace (discovery on a LAN or loopback takes well under this).
constexpr std::chrono::milliseconds kOtherDaemonWindow{1000};

int run(const std::string& config_path, const sigset_t& signals) {
  using namespace sl::daemon;
  using ::sl::files::ConfigError;
  using ::sl::dds::TopicNames;
  using ::sl::dds::currentDdsHost;
  using ::sl::dds::ddsEnvironmentProblems;
  using ::sl::dds::readDdsRequirements;
  const DaemonConfig config = loadConfig(config_path);
  checkDdsEnvironment();
  // One daemon per domain and namespace on this host: the lock arbitrates
  // two that start at once; the DDS check below also sees other hosts.
  std::optional<InstanceLock> instance_lock;
  if (const std::string dir = instanceLockDirectory(); dir.empty())
    logWarning("no directory for the instance lock ($RUNTIME_DIRECTORY, /run/lock, "
               "$XDG_RUNTIME_DIR, /tmp): only the DDS check keeps a second daemon out");
  else
    instance_lock.emplace(dir, config.dds.domain_id, config.dds.ns);
  if (otherDaemonServes(config.dds, kOtherDaemonWindow))
    throw ConfigError("another sl_sensord already serves requests on '" +
                      TopicNames::forNamespace(config.dds.ns).request + "' (domain " +
                      std::to_string(config.dds.domain_id) +
                      "); stop it, or give this one its own dds.namespace");
  std::shared_ptr<void> device_owner;
  EngineDevices devices = openDevices(config, device_owner);
  DdsBridge bridge(config.dds, devices.cameras.front()->id(), config.calibration,
                   config.extra_calibrations);
  if (const std::size_t shm = sl::dds::populateSharedMemoryMappings())
    logInfo("shared memory: page tables of " + std::to_string(shm >> 20) +
            " MiB of iceoryx segments filled in (the first clouds do not fault them)");
  ScanEngine engine(config, std::move(devices),
                    [&bridge](const ScanResult& result) { bridge.publish(result); },
                    bridge.resultContents());
  std::thread server([&] { bridge.serve(engine); });

  const TopicNames topics = TopicNames::forNamespace(config.dds.ns);
  endStartupWatch();  // from here on the loop below takes the signals
  logInfo("ready: sensor '" + std::string(toString(config.sensor)) + "', pattern '" +
          config.runtime.default_pattern + "', domain " + std::to_string(config.dds.domain_id) + ", clouds on '" + topics.points +
          "', requests on '" + topics.request + "'");
  systemdNotify("READY=1");

  const auto watchdog = systemdWatchdogInterval();
  const auto tick = watchdog ? std::chrono::duration_cast<std::chrono::milliseconds>(*watchdog / 3)
                             : std::chrono::milliseconds(500);
  ReloadWorker reloads(loadConfig, kReloadDeadline);
  int signal_number = reload_asked_in_startup ? SIGHUP : 0;
  while (signal_number <= 0 || signal_number == SIGHUP) {
    if (signal_number == SIGHUP) beginReload(config_path, reloads, engine);
    if (auto outcome = reloads.poll()) finishReload(std::move(*outcome), config, engine, bridge);
    // While a reload loads, its outcome is looked at every 50 ms.
    const auto wait = reloads.pending() ? std::min(tick, std::chrono::milliseconds(50)) : tick;
    timespec timeout{static_cast<time_t>(wait.count() / 1000),
                     static_cast<long>((wait.count() % 1000) * 1'000'000)};
    signal_number = sigtimedwait(&signals, nullptr, &timeout);
    // The watchdog is fed only while every pipeline thread is alive.
    if (watchdog && engine.healthy()) systemdNotify("WATCHDOG=1");
  }
  logInfo(std::string("received ") + strsignal(signal_number) + ", shutting down");
  systemdNotify("STOPPING=1");
  bridge.stop();
  server.join();
  return 0;
}

// Start-up (config, devices, DDS) can take a while: a signal in that time
// ends the process at once instead of waiting for the main loop.
void watchStartup(const sigset_t& signals) {
  while (!startup_done) {
    timespec timeout{0, 100'000'000};
    const int signal_number = sigtimedwait(&signals, nullptr, &timeout);
    if (signal_number == SIGINT || signal_number == SIGTERM) {
      sl::daemon::logInfo(std::string("received ") + strsignal(signal_number) +
                          " during start-up, exiting");
      sl::daemon::removeHeldInstanceLockFiles();
      std::_Exit(0);
    }
    // SIGHUP before READY: reloaded once the main loop runs (the file may
    // have changed since start-up read it).
    if (signal_number == SIGHUP) reload_asked_in_startup = true;
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string config_path;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::cout << kUsage;
      return 0;
    } else if (arg == "--config" && i + 1 < argc) {
      config_path = argv[++i];
    } else {
      std::cerr << "sl_sensord: unknown argument '" << arg << "'\n" << kUsage;
      return 2;
    }
  }
  if (config_path.empty()) {
    std::cerr << "sl_sensord: --config FILE is required\n" << kUsage;
    return 2;
  }

  // Before any thread allocates: freed clouds' memory stays in the process
  // (each scan would otherwise page-fault 25 MB buffers in again).
  if (!sl::dds::retainLargeSampleMemory())
    sl::daemon::logWarning("glibc refused the allocator settings for large samples (mallopt): "
                           "clouds may cost page faults");

  // Signals are taken synchronously by the main thread: block them before
  // any thread starts so that every thread inherits the mask.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  startup_watch = std::thread(watchStartup, std::cref(signals));
  try {
    const int rc = run(config_path, signals);
    endStartupWatch();
    if (sl::daemon::ReloadWorker::threadsRunning() > 0) {
      // A reload still blocked in a load: its thread may hold library state
      // that the static destructors would tear down under it.
      sl::daemon::logWarning("exiting with a config reload still loading (abandoned)");
      std::fflush(nullptr);
      std::_Exit(rc);
    }
    return rc;
  } catch (const sl::files::ConfigError& e) {
    sl::daemon::logError(std::string("config error: ") + e.what());
    endStartupWatch();
    return 2;
  } catch (const std::exception& e) {
    sl::daemon::logError(std::string("fatal: ") + e.what());
    endStartupWatch();
    return 1;
  }
}
