#include "sl/pipeline/row_workers.h"

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace sl::pipeline {

struct RowWorkers::Shared {
  std::mutex mutex;
  std::condition_variable wake;  // workers: a new job or stop
  std::condition_variable done;  // caller: a worker finished the job
  // Guarded by mutex:
  std::uint64_t generation = 0;  // bumped per job
  bool stop = false;
  int busy = 0;  // workers still on the current job
  std::exception_ptr error;
  // The current job; written by run() under the mutex before the
  // generation bump, read by the workers after they see it.
  const std::function<void(int, int, int)>* fn = nullptr;
  int rows = 0;
  int block = 1;
  std::atomic<int> next_block{0};
  std::atomic<bool> failed{false};
  std::vector<std::thread> threads;
  // CPUs the workers may use: those the constructing thread could use.
  cpu_set_t allowed;
  bool have_allowed = false;
  int steered_from = -1;  // the caller's CPU the workers were last kept off

  // Keeps the workers off the CPU the caller runs on. Without this, a
  // worker woken after an idle spell was often placed on the caller's CPU
  // (on the VM measured; why the scheduler passed over the idle vCPU was
  // not established) and the two threads took turns on one CPU for
  // milliseconds (BM_DecodeTriangulatePaced with 2 threads: much slower
  // than with the workers kept off; figures in docs/measurements.md,
  // "Processing after idle"). Syscalls only when the caller has
  // moved; a failure leaves the workers as they were (they still run, maybe
  // on the caller's CPU).
  void steerAwayFrom(int cpu) {
    if (!have_allowed || cpu < 0 || cpu == steered_from || threads.empty()) return;
    steered_from = cpu;
    cpu_set_t others = allowed;
    if (cpu < CPU_SETSIZE) CPU_CLR(cpu, &others);
    const cpu_set_t& mask = CPU_COUNT(&others) > 0 ? others : allowed;
    for (std::thread& t : threads) pthread_setaffinity_np(t.native_handle(), sizeof mask, &mask);
  }

  // Takes blocks until none is left; records the first exception.
  void work(int thread) {
    while (!failed.load(std::memory_order_relaxed)) {
      const int begin = next_block.fetch_add(1, std::memory_order_relaxed) * block;
      if (begin >= rows) return;
      try {
        (*fn)(begin, std::min(begin + block, rows), thread);
      } catch (...) {
        std::lock_guard lock(mutex);
        if (!error) error = std::current_exception();
        failed.store(true, std::memory_order_relaxed);
      }
    }
  }

  void workerLoop(int thread) {
    std::uint64_t seen = 0;
    std::unique_lock lock(mutex);
    for (;;) {
      wake.wait(lock, [&] { return stop || generation != seen; });
      if (stop) return;
      seen = generation;
      lock.unlock();
      work(thread);
      lock.lock();
      if (--busy == 0) done.notify_one();
    }
  }
};

RowWorkers::RowWorkers(int threads) : shared_(std::make_unique<Shared>()) {
  if (threads < 1) throw std::invalid_argument("RowWorkers: threads must be >= 1");
  Shared* s = shared_.get();
  s->have_allowed = sched_getaffinity(0, sizeof s->allowed, &s->allowed) == 0;
  for (int i = 1; i < threads; ++i) s->threads.emplace_back([s, i] { s->workerLoop(i); });
}

RowWorkers::~RowWorkers() {
  {
    std::lock_guard lock(shared_->mutex);
    shared_->stop = true;
  }
  shared_->wake.notify_all();
  for (std::thread& t : shared_->threads) t.join();
}

int RowWorkers::threads() const { return static_cast<int>(shared_->threads.size()) + 1; }

int RowWorkers::defaultThreads() {
  return std::clamp(static_cast<int>(std::thread::hardware_concurrency()), 1, 8);
}

void RowWorkers::run(int rows, int block, const std::function<void(int, int, int)>& fn) {
  if (rows <= 0) return;
  if (block < 1) throw std::invalid_argument("RowWorkers::run: block must be >= 1");
  Shared& s = *shared_;
  const int blocks = (rows + block - 1) / block;
  // Workers beyond the block count would only wake to find nothing to do.
  const bool parallel = !s.threads.empty() && blocks > 1;
  {
    std::lock_guard lock(s.mutex);
    s.fn = &fn;
    s.rows = rows;
    s.block = block;
    s.next_block.store(0, std::memory_order_relaxed);
    s.failed.store(false, std::memory_order_relaxed);
    s.error = nullptr;
    if (parallel) {
      s.busy = static_cast<int>(s.threads.size());
      ++s.generation;
    }
  }
  if (parallel) {
    s.steerAwayFrom(sched_getcpu());
    s.wake.notify_all();
  }
  s.work(0);
  std::unique_lock lock(s.mutex);
  s.done.wait(lock, [&] { return s.busy == 0; });
  s.fn = nullptr;
  if (s.error) std::rethrow_exception(std::exchange(s.error, nullptr));
}

}  // namespace sl::pipeline
