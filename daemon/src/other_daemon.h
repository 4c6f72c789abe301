// Start-up check that no other sl_sensord serves the same domain and
// namespace (private to daemon/): two would both answer every request and
// both start on one START. Distinct namespaces (a deliberate multi-sensor
// setup) never collide: their request topics differ.
#pragma once

#include <chrono>
#include <string>

#include "sl/daemon/config.h"

namespace sl::daemon {

// Looks for a reader of rq/<ns>/commandRequest (only a daemon reads
// requests) for up to `window`; returns true as soon as one is matched.
// Throws sl::dds::Error if DDS cannot be set up.
bool otherDaemonServes(const DdsConfig& config, std::chrono::milliseconds window);

}  // namespace sl::daemon
