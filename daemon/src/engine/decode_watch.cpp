#include "engine/decode_watch.h"

namespace sl::daemon {

DecodeWatch::Verdict DecodeWatch::report(const std::string& pattern, const std::string& camera,
                                         const pipeline::DecodeHealth& h, bool first_camera) {
  Verdict v;
  v.implausible = h.implausible;
  if (h.implausible) {
    v.cause = "decode of pattern '" + pattern + "' by camera '" + camera + "' implausible:";
    for (std::size_t i = 0; i < h.problems.size(); ++i) v.cause += (i == 0 ? " " : "; ") + h.problems[i];
  }
  std::lock_guard lock(mutex_);
  if (first_camera) {
    modulated_fraction_ = h.modulatedFraction();
    consistent_fraction_ = h.consistentFraction();
    residual_median_ = h.residual_median;
  }
  if (h.implausible) ++clouds_implausible_;
  return v;
}

void DecodeWatch::setDone(std::uint64_t generation, const std::string& cause) {
  std::lock_guard lock(mutex_);
  if (generation != streak_generation_) {
    streak_generation_ = generation;
    streak_ = 0;
  }
  streak_ = cause.empty() ? 0 : streak_ + 1;
  streak_cause_ = cause;
}

std::string DecodeWatch::degradedCause(std::uint64_t generation) const {
  std::lock_guard lock(mutex_);
  if (generation != streak_generation_ || streak_ < kScansToDegrade) return "";
  return streak_cause_ + " (" + std::to_string(streak_) + " scans in a row)";
}

void DecodeWatch::fill(EngineStatus& s) const {
  std::lock_guard lock(mutex_);
  s.decode_modulated_fraction = modulated_fraction_;
  s.decode_consistent_fraction = consistent_fraction_;
  s.decode_residual_median = residual_median_;
  s.clouds_implausible = clouds_implausible_;
}

}  // namespace sl::daemon
