// Which matched readers of a reliable keep-last writer acknowledge its
// samples, and how many samples each cannot have received (README "No silent
// loss"). Used for rt/<ns>/points.
//
// Cyclone's keep-last writer never waits for a reader that does not
// acknowledge (a stopped process, a keep-all reader whose history is full):
// a sample pushed out of the writer's history (depth d) before a reader
// acknowledged it is gone for that reader, and dds_write reports nothing
// (measured: a reader stopped for 6 s at 10 samples/s missed 56 samples, all
// writes succeeded). The public C API of Cyclone 0.10 has no per-reader
// acknowledgement state: dds_get_matched_subscription_data gives a reader's
// GUID and QoS, dds_wait_for_acks and the writer statistics (rexmit_bytes,
// throttle_count, time_throttle, time_rexmit) cover all readers together.
// Per reader, libddsc exports dds__ddsi_writer_wait_for_acks(writer, reader
// GUID, timeout) (with dds_entity_pin / dds_entity_unpin: how Cyclone's own
// tests wait for one reader's acks); its declaration is in an uninstalled
// header, so reader_acks.cpp declares it. A thread waits on it, reader by
// reader, for everything written so far, which gives per reader the last
// sample known acknowledged ("acked through"). When write n pushes sample
// n - d out of the history, each reliable reader acked through less than
// n - d, and matched before n - d was written, has lost it.
//
// A reader whose participant is silent for longer than its lease (a stopped
// process) is unmatched by Cyclone and matched again, with the same GUID,
// when it resumes; the samples written while it was away never reach it
// (volatile). Its entry is kept by GUID meanwhile (the last kDepartedKept
// readers to go), and on its return everything written after what it had
// acknowledged or been counted as losing is added to its loss, so its count
// continues instead of restarting at 0.
//
// Exact for a reader that stops acknowledging; the thread learns of an
// acknowledgement at most one sample and ~20 ms late, so a reader that
// acknowledges more than about d - 1 sample intervals late is counted as
// losing samples it may yet get. Best-effort readers send no
// acknowledgements: their losses are invisible to the writer (listed, never
// counted), as are those of a keep-last reader that acknowledges and then
// overwrites unread samples in its own history (its choice of QoS).
//
// Thread-safe: written() from the publishing thread, readers() / lost() from
// any thread, one internal thread.
#pragma once

#include <dds/dds.h>

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace sl::daemon {

struct MatchedReaderState {
  std::string guid;           // as Cyclone prints GUIDs: 4 hex words, "prefix:prefix:prefix:entity"
  bool reliable = true;       // false: best effort, its losses are not visible here
  bool acknowledging = true;  // false: more samples unacknowledged than the history keeps
  std::uint64_t lost = 0;     // samples pushed out of the history before it acknowledged them
};

class ReaderAckMonitor {
 public:
  // `writer`: a reliable writer; `history_depth`: its keep-last depth (0 for
  // keep-all: nothing is pushed out, a slow reader makes writes time out
  // instead). Starts the thread; the writer must outlive the monitor.
  ReaderAckMonitor(dds_entity_t writer, std::int32_t history_depth);
  ~ReaderAckMonitor();
  ReaderAckMonitor(const ReaderAckMonitor&) = delete;
  ReaderAckMonitor& operator=(const ReaderAckMonitor&) = delete;

  // After each successful write: counts the sample it pushed out for every
  // reader that had not acknowledged it.
  void written();

  // The readers matched now, in the order they matched.
  std::vector<MatchedReaderState> readers() const;
  // Samples that at least one reader lost, since start-up (readers that
  // have gone away included). A sample more than kLostWindow samples old
  // when a returning reader's gap is counted may be counted twice if
  // another reader lost it too.
  std::uint64_t lost() const { return lost_total_.load(); }

  static constexpr std::size_t kDepartedKept = 256;
  static constexpr std::uint64_t kLostWindow = 4096;

 private:
  struct Reader {
    MatchedReaderState state;
    std::uint64_t order = 0;         // when first seen, for readers()
    unsigned char key[16] = {};      // GUID, network byte order (builtin topic key)
    std::uint64_t acked_through = 0; // samples 1..acked_through acknowledged
    std::uint64_t lost_through = 0;  // samples up to here counted (lost or acked)
    bool seen = false;               // still matched (refresh)
    std::uint64_t departed = 0;      // departure order, in departed_
  };

  void run();
  void refreshMatched();
  // Counts sample `n` in lost_total_ unless already counted; mutex_ held.
  void countLost(std::uint64_t n);
  // A reader matched again after its lease expired: what was written while
  // it was away is lost to it. mutex_ held.
  void welcomeBack(Reader& r, std::uint64_t written_now);
  // True if the reader acknowledged everything written when the call began
  // (or is no longer matched), waiting at most `timeout`.
  bool waitForAcks(const unsigned char key[16], dds_duration_t timeout);

  const dds_entity_t writer_;
  const std::uint64_t depth_;
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> lost_total_{0};
  mutable std::mutex mutex_;
  std::map<dds_instance_handle_t, Reader> readers_;  // guarded by mutex_
  std::map<std::string, Reader> departed_;           // by GUID, guarded by mutex_
  std::uint64_t next_departure_ = 0;                 // guarded by mutex_
  std::vector<bool> counted_ = std::vector<bool>(kLostWindow);  // sample % window; mutex_
  std::uint64_t next_order_ = 0;                     // guarded by mutex_
  std::condition_variable wake_;                     // written() or stop
  bool stopping_ = false;                            // guarded by mutex_
  std::thread thread_;
};

}  // namespace sl::daemon
