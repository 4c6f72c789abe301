// A small persistent thread pool that runs one function over blocks of image
// rows: the calling thread plus (threads - 1) workers started once, by the
// constructor, and joined by the destructor.
//
// Why threads in the pipeline library, which otherwise starts none: the
// stages (Codec, Triangulator) stay thread-free and synchronous; RowWorkers
// is an explicit object that its owner (the daemon's processing thread, a
// benchmark, sl_process) creates and keeps, so who owns which threads stays
// visible. Keeping it here lets the benchmark time exactly the code the
// daemon runs.
#pragma once

#include <functional>
#include <memory>

namespace sl::pipeline {

// Thread-compatible: one run() at a time per instance (the workers are its
// own). run() is synchronous: it returns when every block is done.
class RowWorkers {
 public:
  // threads: total threads that work in run(), the caller included (>= 1;
  // 1 = no worker threads, run() works inline). Throws
  // std::invalid_argument for threads < 1.
  explicit RowWorkers(int threads = defaultThreads());
  ~RowWorkers();  // joins the workers
  RowWorkers(const RowWorkers&) = delete;
  RowWorkers& operator=(const RowWorkers&) = delete;

  int threads() const;

  // Calls fn(begin, end, thread) for the blocks [0, block), [block,
  // 2 block), ... covering rows [0, rows), each block exactly once, on the
  // caller (thread 0) and the workers (threads 1 .. threads() - 1): calls
  // with the same `thread` never overlap, so fn may keep per-thread state
  // indexed by it. Blocks are handed out one at a time in row order (a
  // thread that is descheduled takes fewer). If fn throws, the remaining
  // blocks are skipped and the first exception is rethrown here once all
  // threads are idle again. The workers run on the CPUs the constructing
  // thread could use, minus the one the caller is on when run() starts (when
  // another is left): two threads on one CPU would take turns.
  void run(int rows, int block, const std::function<void(int begin, int end, int thread)>& fn);

  // Hardware threads, clamped to [1, 8].
  static int defaultThreads();

 private:
  struct Shared;
  std::unique_ptr<Shared> shared_;
};

}  // namespace sl::pipeline
