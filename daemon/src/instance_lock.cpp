#include "instance_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>

#include "sl/files/config_error.h"

namespace sl::daemon {

// Moved out of daemon/ (issue 34).
using ::sl::files::ConfigError;

namespace {

bool usableDirectory(const std::string& dir) {
  struct stat st {};
  return !dir.empty() && ::stat(dir.c_str(), &st) == 0 && S_ISDIR(st.st_mode) &&
         ::access(dir.c_str(), W_OK | X_OK) == 0;
}

std::string environment(const char* name) {
  const char* value = std::getenv(name);
  return value ? value : "";
}

// The pid the holder wrote into the file; the holder writes it right after
// taking the lock, so an empty file is read again for a short while.
std::string holderPid(int fd) {
  for (int attempt = 0; attempt < 50; ++attempt) {
    char text[32] = {};
    const ssize_t n = ::pread(fd, text, sizeof text - 1, 0);
    if (n > 0) {
      std::string pid(text, static_cast<std::size_t>(n));
      while (!pid.empty() && (pid.back() == '\n' || pid.back() == ' ')) pid.pop_back();
      if (!pid.empty() && pid.find_first_not_of("0123456789") == std::string::npos) return pid;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return "";
}

// The lock files this process holds (descriptor -> path).
std::mutex held_mutex;
std::map<int, std::string> held_files;

}  // namespace

void removeHeldInstanceLockFiles() {
  std::lock_guard<std::mutex> lock(held_mutex);
  for (const auto& [fd, path] : held_files) {
    if (::ftruncate(fd, 0) != 0) {
    }
    ::unlink(path.c_str());
  }
  held_files.clear();
}

std::string instanceLockDirectory() {
  std::string runtime = environment("RUNTIME_DIRECTORY");
  runtime = runtime.substr(0, runtime.find(':'));
  for (const std::string& dir : {runtime, std::string("/run/lock"), environment("XDG_RUNTIME_DIR"),
                                 std::string("/tmp")})
    if (usableDirectory(dir)) return dir;
  return "";
}

std::string instanceLockName(int domain_id, const std::string& ns) {
  std::string name = ns;
  for (char& c : name)
    if (c == '/') c = '+';
  return "sl_sensord-" + std::to_string(domain_id) + "-" + name + ".lock";
}

InstanceLock::InstanceLock(const std::string& directory, int domain_id, const std::string& ns)
    : path_(directory + "/" + instanceLockName(domain_id, ns)) {
  // The holder removes the file when it exits (below), so a lock taken on a
  // file that is no longer at the path (removed, or replaced by another
  // daemon's new file, between our open and our lock) does not count: then
  // open the path again. A few rounds settle any interleaving of exits.
  for (int attempt = 0; attempt < 16; ++attempt) {
    // Another user's lock file in a sticky directory (/tmp, /run/lock) may
    // not be opened for writing or with O_CREAT (fs.protected_regular):
    // read-only is enough to lock it.
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
    writable_ = fd_ >= 0;
    if (fd_ < 0 && (errno == EACCES || errno == EPERM))
      fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (fd_ < 0)
      throw std::runtime_error(path_ + ": cannot open the instance lock: " + std::strerror(errno));
    int rc;
    do rc = ::flock(fd_, LOCK_EX | LOCK_NB);
    while (rc != 0 && errno == EINTR);
    if (rc != 0) {
      const int error = errno;
      if (error == EWOULDBLOCK) {
        const std::string pid = holderPid(fd_);
        ::close(fd_);
        fd_ = -1;
        throw ConfigError("another sl_sensord (" +
                          (pid.empty() ? std::string("pid unknown") : "pid " + pid) +
                          ") already serves domain " + std::to_string(domain_id) + ", namespace '" +
                          ns + "' on this host (it holds " + path_ +
                          "); stop it, or give this one its own dds.namespace");
      }
      ::close(fd_);
      fd_ = -1;
      throw std::runtime_error(path_ + ": cannot lock: " + std::strerror(error));
    }
    struct stat held {}, named {};
    if (::fstat(fd_, &held) == 0 && ::stat(path_.c_str(), &named) == 0 &&
        held.st_dev == named.st_dev && held.st_ino == named.st_ino) {
      if (writable_) {
        const std::string pid = std::to_string(::getpid()) + "\n";
        if (::ftruncate(fd_, 0) != 0 ||
            ::pwrite(fd_, pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size())) {
          // The lock holds without the pid; a refused daemon then says "pid unknown".
        }
      }
      std::lock_guard<std::mutex> lock(held_mutex);
      held_files[fd_] = path_;
      return;
    }
    ::close(fd_);  // a file no longer at the path: try again
    fd_ = -1;
  }
  throw std::runtime_error(path_ + ": cannot lock: the file keeps being replaced");
}

InstanceLock::~InstanceLock() {
  if (fd_ < 0) return;
  {
    std::lock_guard<std::mutex> lock(held_mutex);
    if (held_files.erase(fd_) == 0) {  // removed already (removeHeldInstanceLockFiles)
      ::close(fd_);
      return;
    }
  }
  // Removed while still locked (a daemon that opened it meanwhile sees it
  // gone and opens the path again); emptied first, in case the directory
  // does not let this process remove it (another user's file in /tmp), so
  // that a refused daemon never reads a pid that is no longer the holder's.
  // Only a killed holder leaves its file (and pid) behind.
  if (writable_ && ::ftruncate(fd_, 0) != 0) {
  }
  ::unlink(path_.c_str());
  ::close(fd_);
}

}  // namespace sl::daemon
