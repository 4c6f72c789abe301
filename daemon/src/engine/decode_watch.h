// Decode health in the daemon (docs/decode-health.md): each scan's health
// from the processing thread's tally, the status's decode fields, the count
// of implausible clouds, and the degraded cause while implausible decodes
// persist. A pattern file that does not describe the projected frames
// decodes to "valid" pixels that are wrong everywhere; this is what keeps
// such clouds off the points topic.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>

#include "sl/daemon/scan_engine.h"  // EngineStatus
#include "sl/pipeline/decode_health.h"

namespace sl::daemon {

// Thread-safe: the processing thread reports, the output thread and status()
// read.
class DecodeWatch {
 public:
  // Scans in a row of one request whose decode was implausible before the
  // scan counts as degraded (one may be a blip: a fast motion, a flash).
  static constexpr int kScansToDegrade = 3;

  // What to do with one camera's scan.
  struct Verdict {
    bool implausible = false;
    std::string cause;  // implausible: pattern, camera and the failed limits
  };
  // The health `h` of the scan of `pattern` by `camera`; `first_camera`:
  // the set's first camera (its health is the status's). Counts an
  // implausible scan.
  Verdict report(const std::string& pattern, const std::string& camera, const pipeline::DecodeHealth& h,
                 bool first_camera);
  // After the reports of one image set of request `generation`: `cause` is
  // the first implausible camera's ("" = every camera plausible, which ends
  // a streak).
  void setDone(std::uint64_t generation, const std::string& cause);

  // Why request `generation` is degraded by its decodes ("" = it is not):
  // its latest kScansToDegrade scans (or more) were implausible.
  std::string degradedCause(std::uint64_t generation) const;

  // The decode fields of the status.
  void fill(EngineStatus& status) const;

 private:
  mutable std::mutex mutex_;
  double modulated_fraction_ = 0, consistent_fraction_ = 0, residual_median_ = 0;
  std::uint64_t clouds_implausible_ = 0;
  std::uint64_t streak_generation_ = 0;
  int streak_ = 0;          // implausible scans in a row of streak_generation_
  std::string streak_cause_;  // the latest of them
};

}  // namespace sl::daemon
