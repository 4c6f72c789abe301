// Counts the samples of a topic that Cyclone drops because they fail to
// deserialize (an enum out of range, a truncated or garbled sample, e.g.
// from a look-alike type). Cyclone's receive path drops such a sample before
// any reader sees it and only logs a warning, "deserialization
// <topic>/<type> failed", so the count comes from its log sink.
//
// Cyclone has one log sink per process. A process-wide registry installs it
// once and hands each such warning to every live counter of that topic and
// type, so several bridges in one process each count their own topic (and
// two counting one topic both count it). Every other message goes to stderr
// as with Cyclone's default sink; of a counter's dropped samples the first 10
// lines and then every 1000th are printed, so a flood of garbage cannot flood
// the log.
//
// Thread-safe: the sink runs on Cyclone's threads while counters come and go.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <string_view>

namespace sl::dds {

class MalformedSampleCounter {
 public:
  // Counts from now on, until destroyed. Create it before the topic's reader
  // (a sample may fail as soon as the reader is matched). With
  // `ignore_fast_dds`, samples from Fast DDS writers (Cyclone's warning says
  // "vendor 1.15": eProsima) are neither counted nor logged: another
  // participant serves them (fastdds_services.h).
  MalformedSampleCounter(const std::string& topic_name, const std::string& type_name,
                         bool ignore_fast_dds = false);
  ~MalformedSampleCounter();
  MalformedSampleCounter(const MalformedSampleCounter&) = delete;
  MalformedSampleCounter& operator=(const MalformedSampleCounter&) = delete;

  std::uint64_t count() const { return count_.load(); }

  // The text Cyclone's warning contains for this counter's samples.
  const std::string& needle() const { return needle_; }
  // Counts one dropped sample; true if its log line should be printed.
  bool add();
  // Whether the warning `text` is about a sample this counter leaves alone.
  bool ignores(std::string_view text) const;

 private:
  const std::string needle_;  // "deserialization <topic>/<type> failed"
  const bool ignore_fast_dds_;
  std::atomic<std::uint64_t> count_{0};
};

}  // namespace sl::dds
