#include "reload_worker.h"

#include <atomic>
#include <exception>
#include <mutex>
#include <system_error>
#include <thread>

namespace sl::daemon {

namespace {
std::atomic<int> threads_running{0};
}  // namespace

struct ReloadWorker::State {
  std::mutex mutex;
  bool returned = false;
  std::optional<DaemonConfig> config;
  std::string error;
};

ReloadWorker::ReloadWorker(Loader loader, std::chrono::milliseconds deadline)
    : loader_(std::move(loader)), deadline_(deadline) {}

ReloadWorker::~ReloadWorker() = default;

int ReloadWorker::threadsRunning() { return threads_running.load(); }

std::string ReloadWorker::begin(const std::string& path, Clock::time_point now) {
  if (state_) {
    std::lock_guard<std::mutex> lock(state_->mutex);
    if (!state_->returned) {
      const auto seconds = std::chrono::duration_cast<std::chrono::seconds>(now - begun_).count();
      return "the reload of " + path_ + " begun " + std::to_string(seconds) +
             " s ago has not returned (a file that blocks, e.g. a FIFO, or a file system that "
             "does not answer)";
    }
  }
  auto state = std::make_shared<State>();
  ++threads_running;
  try {
    // The thread owns what it uses (the state, a copy of the loader and the
    // path): it may outlive this object.
    std::thread([state, loader = loader_, path] {
      std::optional<DaemonConfig> config;
      std::string error;
      try {
        config = loader(path);
      } catch (const std::exception& e) {
        error = e.what();
      } catch (...) {
        error = "unknown error";
      }
      {
        std::lock_guard<std::mutex> lock(state->mutex);
        state->config = std::move(config);
        state->error = std::move(error);
        state->returned = true;
      }
      --threads_running;
    }).detach();
  } catch (const std::system_error& e) {
    --threads_running;
    state->returned = true;
    state->error = std::string("cannot start the reload thread: ") + e.what();
  }
  state_ = std::move(state);
  path_ = path;
  begun_ = now;
  due_ = now + deadline_;
  pending_ = true;
  return "";
}

std::optional<ReloadWorker::Outcome> ReloadWorker::poll(Clock::time_point now) {
  if (!pending_) return std::nullopt;
  Outcome outcome;
  outcome.path = path_;
  {
    std::lock_guard<std::mutex> lock(state_->mutex);
    if (state_->returned) {
      outcome.kind = state_->config ? Outcome::Kind::kLoaded : Outcome::Kind::kFailed;
      outcome.config = std::move(state_->config);
      outcome.error = state_->error;
    } else if (now >= due_) {
      outcome.kind = Outcome::Kind::kTimedOut;
    } else {
      return std::nullopt;
    }
  }
  pending_ = false;
  return outcome;
}

}  // namespace sl::daemon
