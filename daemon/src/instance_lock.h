// One sl_sensord per DDS domain and namespace on a host, race-free (private
// to daemon/): an exclusive flock(2) on a file named after both, taken
// before any device is opened and held for the life of the process. Two
// daemons started at the same moment contend for the same lock: exactly one
// gets it. The kernel releases it when the holder exits, however it exits.
// Complements the DDS-level check (other_daemon.h), which also sees daemons
// on other hosts or with another lock directory but cannot arbitrate two
// daemons that start within its discovery window.
#pragma once

#include <string>

namespace sl::daemon {

// Where the lock file lives: the first of $RUNTIME_DIRECTORY (systemd's
// RuntimeDirectory=, its first entry), /run/lock, $XDG_RUNTIME_DIR and /tmp
// that is a directory this process may create files in; "" if none is.
std::string instanceLockDirectory();

// "sl_sensord-<domain>-<namespace>.lock", a '/' of the namespace written as
// '+' (neither '-' nor '+' can occur in a namespace: one file per pair).
std::string instanceLockName(int domain_id, const std::string& ns);

// Empties and removes the files of the locks this process holds, for an
// exit that skips destructors (std::_Exit during start-up); the locks go with
// the process.
void removeHeldInstanceLockFiles();

class InstanceLock {
 public:
  // Takes the lock <directory>/instanceLockName(domain_id, ns) without
  // waiting and writes this process's pid into the file. Throws ConfigError
  // naming the holder's pid and the file when another process holds it,
  // std::runtime_error when the file cannot be opened or locked.
  InstanceLock(const std::string& directory, int domain_id, const std::string& ns);
  ~InstanceLock();  // closes the file: the lock is released (the file stays)
  InstanceLock(const InstanceLock&) = delete;
  InstanceLock& operator=(const InstanceLock&) = delete;

  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  bool writable_ = false;  // opened for writing: the pid is written
  std::string path_;
};

}  // namespace sl::daemon
