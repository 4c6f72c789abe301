// sl_first_access: what a process's first access to a page of shared memory
// costs, with its page table already filled in (README, "Measured: delivery").
//
//   sl_first_access [MiB]        (default 200)
//
// Creates a /dev/shm file of MiB, allocates and writes it in a child process
// (as RouDi and iceoryx-prefault do for the segments), then, in this process,
// for each of three ways of preparing a fresh mapping of it:
//   populate       madvise(MADV_POPULATE_WRITE) only
//   populate+read  that, then one byte read per page (populateSharedMemoryMappings)
//   none           nothing
// prints the time of the preparation and of copying 25 MB into three regions
// not touched before, and out of a fourth. On bare metal a populated mapping
// copies at memory speed; on a VM with shadow page tables the first access of
// each page by each process costs an exit to the hypervisor, which the
// guest's page-fault counters do not show.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

constexpr std::size_t kMiB = std::size_t{1} << 20;
constexpr std::size_t kCopy = 25 * kMiB;  // about one cloud

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

long minorFaults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

int run(std::size_t mib) {
  const std::size_t size = mib * kMiB;
  if (size < 4 * 2 * kCopy) {
    std::fprintf(stderr, "sl_first_access: at least %zu MiB\n", 8 * kCopy / kMiB);
    return 2;
  }
  const std::string path = "/dev/shm/sl_first_access_" + std::to_string(getpid());
  const int fd = open(path.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  if (fd < 0 || ftruncate(fd, static_cast<off_t>(size)) != 0) {
    std::perror(path.c_str());
    return 1;
  }
  unlink(path.c_str());  // the descriptor keeps it
  const long page = sysconf(_SC_PAGESIZE);
  // Another process allocates and writes every page.
  if (const pid_t child = fork(); child == 0) {
    void* m = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (m == MAP_FAILED) _exit(1);
    std::memset(m, 0x5a, size);
    _exit(0);
  } else {
    int status = 0;
    waitpid(child, &status, 0);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return 1;
  }
  std::vector<unsigned char> src(kCopy, 1), dst(kCopy, 2);  // written: no first touches below
  std::printf("sl_first_access: %zu MiB of /dev/shm written by another process; 25 MB copies\n", mib);
  for (const char* how : {"populate", "populate+read", "none"}) {
    auto* m = static_cast<unsigned char*>(mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0));
    if (m == MAP_FAILED) return 1;
    const auto t0 = std::chrono::steady_clock::now();
    if (std::strcmp(how, "none") != 0) madvise(m, size, MADV_POPULATE_WRITE);
    if (std::strcmp(how, "populate+read") == 0) {
      unsigned char sink = 0;
      for (std::size_t o = 0; o < size; o += static_cast<std::size_t>(page))
        sink ^= static_cast<volatile unsigned char*>(m)[o];
      static_cast<void>(sink);
    }
    const double prepare_ms = msSince(t0);
    const long faults0 = minorFaults();
    std::printf("  %-14s prepare %6.1f ms; copies in:", how, prepare_ms);
    for (int k = 0; k < 3; ++k) {
      const auto t = std::chrono::steady_clock::now();
      std::memcpy(m + static_cast<std::size_t>(k) * 2 * kCopy, src.data(), kCopy);
      std::printf(" %5.1f", msSince(t));
    }
    const auto t = std::chrono::steady_clock::now();
    std::memcpy(dst.data(), m + 6 * kCopy, kCopy);
    std::printf(" ms, out: %5.1f ms; page faults in the copies: %ld\n", msSince(t), minorFaults() - faults0);
    munmap(m, size);
  }
  close(fd);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const long mib = argc > 1 ? std::strtol(argv[1], nullptr, 10) : 200;
  if (argc > 2 || mib <= 0) {
    std::fprintf(stderr, "usage: sl_first_access [MiB]\n");
    return 2;
  }
  return run(static_cast<std::size_t>(mib));
}
