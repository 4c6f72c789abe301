#include "sl/dds/malformed_samples.h"

#include <algorithm>
#include <cstdio>
#include <mutex>
#include <string_view>
#include <vector>

#include <dds/ddsrt/log.h>

namespace sl::dds {

namespace {

// The live counters. Never destroyed: Cyclone's threads may log until the
// process ends, after static destructors ran.
class Registry {
 public:
  static Registry& instance() {
    static Registry* registry = new Registry;
    return *registry;
  }

  void add(MalformedSampleCounter* counter) {
    // Installed once, outside mutex_: Cyclone calls the sink holding its log
    // lock, and the sink takes mutex_, so taking them the other way round
    // (mutex_, then dds_set_log_sink's lock) could deadlock.
    std::call_once(installed_, [] { dds_set_log_sink(&Registry::sink, nullptr); });
    const std::lock_guard<std::mutex> lock(mutex_);
    counters_.push_back(counter);
  }

  void remove(MalformedSampleCounter* counter) {
    const std::lock_guard<std::mutex> lock(mutex_);
    counters_.erase(std::remove(counters_.begin(), counters_.end(), counter), counters_.end());
  }

 private:
  static void sink(void*, const dds_log_data_t* data) {
    const std::string_view text(data->message, data->size);
    bool print = true;
    if (text.find("deserialization ") != std::string_view::npos) {
      Registry& self = instance();
      const std::lock_guard<std::mutex> lock(self.mutex_);
      bool counted = false;
      for (MalformedSampleCounter* counter : self.counters_) {
        if (text.find(counter->needle()) == std::string_view::npos) continue;
        const bool print_this = !counter->ignores(text) && counter->add();
        print = counted ? (print || print_this) : print_this;
        counted = true;
      }
    }
    // Cyclone's message comes without its line end.
    if (print) std::fprintf(stderr, "%.*s\n", static_cast<int>(text.size()), text.data());
  }

  std::once_flag installed_;
  std::mutex mutex_;
  std::vector<MalformedSampleCounter*> counters_;  // guarded by mutex_
};

}  // namespace

MalformedSampleCounter::MalformedSampleCounter(const std::string& topic_name,
                                               const std::string& type_name, bool ignore_fast_dds)
    : needle_("deserialization " + topic_name + "/" + type_name + " failed"),
      ignore_fast_dds_(ignore_fast_dds) {
  Registry::instance().add(this);
}

MalformedSampleCounter::~MalformedSampleCounter() { Registry::instance().remove(this); }

bool MalformedSampleCounter::ignores(std::string_view text) const {
  // Cyclone: "data(application, vendor 1.15): <guid> #<seq>: deserialization ..."
  return ignore_fast_dds_ && text.find("vendor 1.15)") != std::string_view::npos;
}

bool MalformedSampleCounter::add() {
  const std::uint64_t n = ++count_;
  return n <= 10 || n % 1000 == 0;
}

}  // namespace sl::dds
