// Issue 36 probes (items 2 and 5), each a test that failed on the daemon
// before the change (docs/operations.md, "Hardening", has the table):
// - [lock]     two daemons started at the same moment on one namespace: both
//              ran; now exactly one does, the other exits 2 naming its pid;
// - [reload]   a reload whose config names a FIFO (a texture): the main
//              thread blocked in it and SIGTERM was ignored; now the load runs
//              on a worker with a deadline, SIGTERM ends the daemon in 2 s
//              and the status shows the refused reload;
// - [precheck] a pattern naming a camera the sensor lacks, a huge roi:
//              exit 1 "no camera with this id" after opening devices; now
//              exit 2 naming the key, before any device;
// - [files]    calibration, key-mapping and projector-response files that
//              are FIFOs, alias bombs or two documents: hung or were accepted;
//              now one ConfigError naming the file.
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "daemon_process.h"
#include "instance_lock.h"
#include "reload_worker.h"
#include "sl/files/calibration_io.h"
#include "sl/daemon/config.h"
#include "sl/files/config_error.h"
#include "support/time_scale.h"

using namespace std::chrono_literals;
using sl::test::kTimeScale;
using sl::test::scaledBound;

namespace {

// A fresh folder under /tmp for one test case; removed when done.
struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& name)
      : path("/tmp/sl_test_" + name + "_" + std::to_string(::getpid())) {
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// sl_sensord --config `config` with its stderr in `log` (through a shell
// that execs it: the child's pid is the daemon's).
sl::test::ChildProcess daemonLoggingTo(const std::string& config, const std::string& log) {
  return sl::test::ChildProcess({"/bin/sh", "-c",
                                 "exec '" + std::string(SL_BINARY_DIR) + "/daemon/sl_sensord' --config '" +
                                     config + "' 2> '" + log + "'"});
}

}  // namespace

// --- one daemon per domain and namespace ---------------------------------

TEST_CASE("the instance lock admits one holder and names it to the next", "[lock]") {
  using sl::daemon::InstanceLock;
  TempDir dir("lock");
  CHECK(sl::daemon::instanceLockName(7, "a/b") == "sl_sensord-7-a+b.lock");
  CHECK(sl::daemon::instanceLockName(7, "a_b") != sl::daemon::instanceLockName(7, "a/b"));
  {
    InstanceLock first(dir.path.string(), 7, "a/b");
    CHECK(readText(first.path()) == std::to_string(::getpid()) + "\n");
    // Another open file description of the same file contends like another
    // process would.
    try {
      InstanceLock second(dir.path.string(), 7, "a/b");
      FAIL("a second lock was granted");
    } catch (const sl::files::ConfigError& e) {
      const std::string what = e.what();
      INFO(what);
      CHECK(what.find("another sl_sensord (pid " + std::to_string(::getpid()) + ")") != std::string::npos);
      CHECK(what.find("domain 7, namespace 'a/b'") != std::string::npos);
      CHECK(what.find(first.path()) != std::string::npos);
    }
    InstanceLock other_namespace(dir.path.string(), 7, "a");  // no contention
    InstanceLock other_domain(dir.path.string(), 8, "a/b");
  }
  // Released with its holder, which removes the file.
  CHECK(!std::filesystem::exists(dir / sl::daemon::instanceLockName(7, "a/b")));
  InstanceLock again(dir.path.string(), 7, "a/b");
  CHECK(std::filesystem::exists(again.path()));
  CHECK(!sl::daemon::instanceLockDirectory().empty());
}

// Before the lock, the DDS check let both run (3 of 3 tries): neither saw
// the other's request reader within its window.
TEST_CASE("two daemons started at the same moment on one namespace: exactly one runs", "[lock]") {
  sl::test::useLoopbackDds();
  TempDir dir("two_daemons");
  constexpr int kRounds = 20;
  for (int round = 0; round < kRounds; ++round) {
    INFO("round " << round);
    const std::string ns = sl::test::uniqueNamespace("two") + "_" + std::to_string(round);
    const std::string config = sl::test::writeConfigFile(sl::test::simConfig(ns), ns);
    const std::string log_a = dir / ("a" + std::to_string(round)), log_b = dir / ("b" + std::to_string(round));
    auto a = daemonLoggingTo(config, log_a);
    auto b = daemonLoggingTo(config, log_b);
    REQUIRE(a.started());
    REQUIRE(b.started());
    // The loser leaves right after loading the config; the winner goes on.
    std::optional<int> a_exit, b_exit;
    const auto deadline = std::chrono::steady_clock::now() + scaledBound(15s);
    while (!a_exit && !b_exit && std::chrono::steady_clock::now() < deadline) {
      a_exit = a.waitExit(0ms);
      if (!a_exit) b_exit = b.waitExit(0ms);
      std::this_thread::sleep_for(10ms);
    }
    REQUIRE((a_exit || b_exit));  // before the lock: both still ran
    sl::test::ChildProcess& winner = a_exit ? b : a;
    const std::string loser_log = readText(a_exit ? log_a : log_b);
    INFO("refused daemon's log: " << loser_log);
    CHECK((a_exit ? *a_exit : *b_exit) == 2);
    CHECK(loser_log.find("another sl_sensord (pid " + std::to_string(winner.pid()) +
                         ") already serves domain 0, namespace '" + ns + "'") != std::string::npos);
    // The winner still runs; in the first round it is seen serving requests.
    CHECK(!winner.waitExit(200ms));
    if (round == 0) {
      sl::client::ClientOptions options;
      options.ns = ns;
      options.subscribe_points = false;
      sl::client::SensorClient client(options);
      CHECK(client.waitForDaemon(scaledBound(20s)));
    }
    CHECK(winner.terminate(5s) == 0);
    std::remove(config.c_str());
  }
}

// --- reloads that block ---------------------------------------------------

namespace {

// A loader as naive as the old one: std::ifstream on the path, which blocks
// in open() on a FIFO without a writer.
sl::daemon::DaemonConfig naiveLoader(const std::string& path) {
  std::ifstream in(path);
  std::string word;
  in >> word;
  throw sl::files::ConfigError(path + ": read '" + word + "'");
}

// Opens the FIFO for writing (a blocked reader then opens too), writes a
// word and closes: the naive loader returns.
void unblock(const std::string& fifo) {
  const int fd = ::open(fifo.c_str(), O_WRONLY);
  REQUIRE(fd >= 0);
  REQUIRE(::write(fd, "unblocked\n", 10) == 10);
  ::close(fd);
}

}  // namespace

TEST_CASE("a reload past its deadline is refused and never waited for", "[reload]") {
  using sl::daemon::ReloadWorker;
  using Kind = ReloadWorker::Outcome::Kind;
  TempDir dir("reload_worker");
  const std::string fifo = dir / "config.fifo";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  const int threads_before = ReloadWorker::threadsRunning();
  const auto t0 = ReloadWorker::Clock::now();
  {
    ReloadWorker worker(naiveLoader, 200ms);
    REQUIRE(worker.begin(fifo, t0).empty());
    CHECK(worker.pending());
    CHECK(!worker.poll(t0 + 100ms));  // within the deadline: no outcome yet
    const auto late = worker.poll(t0 + 200ms);
    REQUIRE(late);
    CHECK(late->kind == Kind::kTimedOut);
    CHECK(late->path == fifo);
    CHECK(!worker.pending());
    CHECK(!worker.poll(t0 + 300ms));  // given once
    // While the abandoned load blocks, another reload is refused (a second
    // thread would block on the same file), naming the first.
    const std::string refused = worker.begin(fifo, t0 + 3s);
    CHECK(refused.find("the reload of " + fifo + " begun 3 s ago has not returned") != std::string::npos);
    CHECK(ReloadWorker::threadsRunning() == threads_before + 1);
  }  // destroyed with the load still blocked: returns at once
  const auto destroyed = ReloadWorker::Clock::now();
  CHECK(destroyed - t0 < 1s);
  unblock(fifo);
  for (int i = 0; i < 500 && ReloadWorker::threadsRunning() > threads_before; ++i)
    std::this_thread::sleep_for(10ms);
  CHECK(ReloadWorker::threadsRunning() == threads_before);

  // A load that returns in time: its result, or its error.
  ReloadWorker worker([](const std::string& path) {
                        if (path == "bad") throw sl::files::ConfigError("bad: no such key");
                        return sl::daemon::parseConfig(readText(sl::test::sourcePath("config/sim.yaml")),
                                                       "sim.yaml");
                      },
                      5s);
  for (const std::string path : {"good", "bad"}) {
    REQUIRE(worker.begin(path).empty());
    std::optional<ReloadWorker::Outcome> outcome;
    for (int i = 0; i < 500 && !outcome; ++i) {
      std::this_thread::sleep_for(10ms);
      outcome = worker.poll();
    }
    REQUIRE(outcome);
    if (path == "good") {
      CHECK(outcome->kind == Kind::kLoaded);
      REQUIRE(outcome->config);
      CHECK(outcome->config->patterns.size() == 2);
    } else {
      CHECK(outcome->kind == Kind::kFailed);
      CHECK(outcome->error == "bad: no such key");
    }
  }
}

// Before: SIGHUP read the new config on the main thread, which blocked for
// ever in the texture FIFO; the status showed nothing and SIGTERM was
// ignored (alive 10 s later, SIGKILL needed).
TEST_CASE("SIGTERM ends the daemon within 2 s whatever a reload is doing", "[reload]") {
  sl::test::useLoopbackDds();
  TempDir dir("reload_fifo");
  const std::string ns = sl::test::uniqueNamespace("reload_fifo");
  YAML::Node root = sl::test::simConfig(ns);
  const std::string config = dir / "sl.yaml";
  std::ofstream(config) << root;
  sl::test::DaemonProcess daemon(config);
  REQUIRE(daemon.started());
  sl::client::ClientOptions options;
  options.ns = ns;
  options.subscribe_points = false;
  sl::client::SensorClient client(options);
  REQUIRE(client.waitForDaemon(scaledBound(20s)));

  // The plane's texture is a FIFO without a writer: a naive reader blocks.
  const std::string fifo = dir / "albedo.png";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  YAML::Node texture;
  texture["file"] = fifo;
  texture["width_mm"] = 200;
  root["sim"]["scene"][0]["plane"]["texture"] = texture;
  std::ofstream(config) << root;
  daemon.signal(SIGHUP);
  // The refusal is in the status: refused at once by the bounded reader, or
  // by the deadline (5 s) of a load that blocked.
  const auto refused = sl::test::statusWhen(
      client, [](const sl::client::StatusInfo& s) { return s.last_error.find("config reload") != std::string::npos; },
      scaledBound(15s));
  REQUIRE(refused);
  INFO("last_error: " << refused->last_error);
  CHECK(refused->last_error.find("config reload") == 0);
  CHECK((refused->last_error.find(fifo) != std::string::npos ||
         refused->last_error.find("did not finish") != std::string::npos));
  CHECK(refused->errors_reported >= 1);

  // A load that really blocks: a recording given as an MCAP file that is a
  // FIFO (the replay reader opens it with std::ifstream, which no bounded
  // check precedes). The deadline refuses the reload; the daemon keeps
  // taking signals.
  const std::string mcap = dir / "recording.mcap";
  REQUIRE(::mkfifo(mcap.c_str(), 0600) == 0);
  YAML::Node replay = YAML::Clone(root);
  replay["sensor"] = "replay";
  replay["calibration"] = sl::test::sourcePath("config/hardware-paper-calibration.yaml");
  replay["replay"]["file"] = mcap;
  std::ofstream(config) << replay;
  daemon.signal(SIGHUP);
  const auto timed_out = sl::test::statusWhen(
      client, [](const sl::client::StatusInfo& s) { return s.last_error.find("did not finish") != std::string::npos; },
      scaledBound(15s));
  REQUIRE(timed_out);
  CHECK(timed_out->last_error.find("config reload refused: loading " + config +
                                   " did not finish within 5 s") == 0);
  // A further reload is refused while that load blocks.
  daemon.signal(SIGHUP);
  const auto still = sl::test::statusWhen(
      client, [](const sl::client::StatusInfo& s) { return s.last_error.find("has not returned") != std::string::npos; },
      scaledBound(10s));
  REQUIRE(still);
  CHECK(still->last_error.find("config reload refused: the reload of " + config) == 0);

  // SIGTERM with that load still blocked: the daemon ends within 2 s.
  const auto t0 = std::chrono::steady_clock::now();
  CHECK(daemon.terminate(2s) == 0);
  const auto seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  INFO("exit after " << seconds << " s");
  CHECK(seconds < 2.0 * kTimeScale);
}

// --- config checks before any device --------------------------------------

namespace {

// config/hardware-paper.yaml (two Aravis cameras that this machine lacks)
// written into `dir` with its calibration, after `edit`.
template <typename Edit>
std::string hardwareConfig(const TempDir& dir, const std::string& ns, Edit edit) {
  std::filesystem::copy_file(sl::test::sourcePath("config/hardware-paper-calibration.yaml"),
                             dir / "hardware-paper-calibration.yaml",
                             std::filesystem::copy_options::overwrite_existing);
  YAML::Node root = YAML::LoadFile(sl::test::sourcePath("config/hardware-paper.yaml"));
  root["dds"]["namespace"] = ns;
  edit(root);
  const std::string path = dir / "hardware.yaml";
  std::ofstream(path) << root;
  return path;
}

}  // namespace

// Before: the devices were opened first, and the missing camera "top" ended
// the daemon with exit 1 ("no camera with this id"): systemd restarted it for
// ever. The same mistakes are now config errors (exit 2) before any device.
TEST_CASE("config mistakes that need no device are exit 2 before any device opens", "[precheck]") {
  sl::test::useLoopbackDds();
  TempDir dir("precheck");
  struct Case {
    std::string what, expected;
    std::function<void(YAML::Node&)> edit;
  };
  const std::vector<Case> cases = {
      {"a pattern names an unknown camera",
       "key 'patterns': pattern '3+3_both' names camera 'nope', which the sensor does not have "
       "(its cameras: top, left)",
       [](YAML::Node& root) { root["patterns"][2]["cameras"].push_back("nope"); }},
      {"a pattern names a camera without calibration",
       "pattern '3+3_both' names camera 'left', which has no calibration",
       [](YAML::Node& root) { root["patterns"][2]["cameras"].push_back("left"); }},
      {"a huge roi", "key 'cameras[0].roi.width': x + width must be at most 16384",
       [](YAML::Node& root) { root["cameras"][0]["roi"]["width"] = 100000000; }},
      {"a roi that differs from the calibration",
       "camera 'top': roi 1280x1080 differs from its calibration's 1440x1080 images",
       [](YAML::Node& root) { root["cameras"][0]["roi"]["width"] = 1280; }},
  };
  for (const Case& c : cases) {
    INFO(c.what);
    const std::string config = hardwareConfig(dir, sl::test::uniqueNamespace("precheck"), c.edit);
    // In-process: loading refuses it.
    try {
      sl::daemon::loadConfig(config);
      FAIL("loaded");
    } catch (const sl::files::ConfigError& e) {
      INFO(e.what());
      CHECK(std::string(e.what()).find(c.expected) != std::string::npos);
    }
    // The daemon: exit 2 with that message, no device touched.
    const std::string log = dir / "daemon.log";
    auto daemon = daemonLoggingTo(config, log);
    REQUIRE(daemon.started());
    const auto rc = daemon.waitExit(scaledBound(20s));
    const std::string text = readText(log);
    INFO(text);
    CHECK(rc == 2);
    CHECK(text.find(c.expected) != std::string::npos);
    CHECK(text.find("no camera with this id") == std::string::npos);
  }
  // The engine's own check (against the opened devices) names the same
  // mistake for the simulated sensor, now found at load.
  YAML::Node sim = sl::test::simConfig("precheck_sim");
  sim["patterns"][1]["cameras"].push_back("sim_left");
  std::ostringstream text;
  text << sim;
  CHECK_THROWS_WITH(sl::daemon::parseConfig(text.str(), "sim.yaml"),
                    Catch::Contains("pattern '3+3_both' names camera 'sim_left', which the sensor "
                                    "does not have (its cameras: sim_top)"));
  sim["sim"]["second_camera"]["camera_id"] = "sim_left";
  sim["sim"]["second_camera"]["calibration"] = YAML::Clone(sim["sim"]["rig"]["calibration"]);
  text.str("");
  text << sim;
  CHECK_NOTHROW(sl::daemon::parseConfig(text.str(), "sim.yaml"));
}

// --- calibration files through the bounded reader ---------------------------

TEST_CASE("calibration, key-mapping and projector-response files are read bounded", "[files]") {
  using sl::files::ConfigError;
  TempDir dir("calibration_files");
  // A FIFO: loadProjectorResponse and loadOpenCvCalibration opened it and
  // blocked for ever; now refused before any read. (The test runs the
  // loaders on a thread so that the old behaviour fails instead of hanging.)
  const auto refusedWithin = [](const std::function<void()>& load, const std::string& words) {
    auto done = std::make_shared<std::atomic<int>>(0);  // 1 refused as expected, 2 otherwise
    auto message = std::make_shared<std::string>();
    std::thread([load, words, done, message] {
      try {
        load();
        *message = "accepted";
      } catch (const ConfigError& e) {
        *message = e.what();
        done->store(message->find(words) != std::string::npos ? 1 : 2);
        return;
      } catch (const std::exception& e) {
        *message = std::string("not a ConfigError: ") + e.what();
      }
      done->store(2);
    }).detach();  // left blocked (and leaked) if the reader hangs
    for (int i = 0; i < 300 && done->load() == 0; ++i) std::this_thread::sleep_for(10ms);
    INFO("message: " << *message);
    CHECK(done->load() == 1);
  };
  const std::string fifo_yaml = dir / "fifo.yaml";
  const std::string fifo_xml = dir / "fifo.xml";
  REQUIRE(::mkfifo(fifo_yaml.c_str(), 0600) == 0);
  REQUIRE(::mkfifo(fifo_xml.c_str(), 0600) == 0);
  refusedWithin([&] { sl::files::loadProjectorResponse(fifo_yaml); }, "is a FIFO");
  refusedWithin([&] { sl::files::loadCalibration(fifo_yaml); }, "is a FIFO");
  refusedWithin([&] { sl::files::loadCalibration(fifo_xml); }, "is a FIFO");
  refusedWithin([&] { sl::files::loadSlSensorCalibration(fifo_yaml, fifo_xml); }, "is a FIFO");
  refusedWithin(
      [&] {
        sl::files::loadOpenCvCalibration(
            fifo_xml, sl::files::parseOpenCvCalibrationKeys(
                          "camera.matrix=K,camera.distortion=k,camera.width=8,camera.height=8,"
                          "projector.matrix=P,projector.distortion=p,projector.width=8,"
                          "projector.height=8,rotation=R,translation=T"));
      },
      "is a FIFO");
  const std::string zero = dir / "zero.yaml";  // a device behind a name that looks right
  std::filesystem::create_symlink("/dev/zero", zero);
  refusedWithin([&] { sl::files::loadCalibration(zero); }, "is a device");

  // Alias bombs and second documents: yaml-cpp read them whole (the second
  // document silently ignored).
  const std::string bomb = dir / "bomb.yaml";
  {
    std::ofstream out(bomb);
    out << "format: sl-sensor-calibration/1\na: &a [x, x, x, x, x, x, x, x, x]\n";
    for (char c = 'b'; c <= 'z'; ++c)
      out << c << ": &" << c << " [*" << char(c - 1) << ", *" << char(c - 1) << ", *"
          << char(c - 1) << ", *" << char(c - 1) << "]\n";
  }
  refusedWithin([&] { sl::files::loadCalibration(bomb); }, "aliases");
  refusedWithin([&] { sl::files::parseOpenCvCalibrationKeys(bomb); }, "aliases");
  const std::string two = dir / "two.yaml";
  {
    // A complete calibration followed by a second document.
    std::ofstream out(two);
    out << readText(sl::test::sourcePath("config/hardware-paper-calibration.yaml"))
        << "---\nformat: sl-sensor-calibration/1\n";
  }
  refusedWithin([&] { sl::files::loadCalibration(two); }, "more than one YAML document");
  const std::string response = dir / "response.yaml";
  std::ofstream(response) << "format: sl-sensor-projector-response/1\ngamma: 2.2\n---\ngamma: 1\n";
  refusedWithin([&] { sl::files::loadProjectorResponse(response); }, "more than one YAML document");
  // Larger than the kind's limit: refused before reading.
  const std::string big = dir / "big.yaml";
  std::ofstream(big).close();
  std::filesystem::resize_file(big, 17 << 20);  // sparse
  refusedWithin([&] { sl::files::loadCalibration(big); }, "more than the limit");

  // Good files still load, parsed from the text read once.
  const auto own = sl::files::loadCalibration(sl::test::sourcePath("config/hardware-paper-calibration.yaml"));
  CHECK(own.calibration.camera.width == 1440);
  const std::string good_response = dir / "good_response.yaml";
  std::ofstream(good_response) << "format: sl-sensor-projector-response/1\ngamma: 2.2\n";
  CHECK(sl::files::loadProjectorResponse(good_response).size() > 2);
}
