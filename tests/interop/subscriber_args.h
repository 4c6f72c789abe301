// Command line shared by the two interop subscribers:
//   PROGRAM --topic NAME [--domain N] [--count N] [--timeout SECONDS]
// Both print "ready" once a writer of the topic is matched, then one
// digestLine() per cloud, and exit 0 after --count clouds, 1 on timeout
// (discovery and clouds together must fit in --timeout), 2 on bad arguments
// or a middleware failure.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>

namespace sl::interop {

struct SubscriberArgs {
  std::string topic;
  int domain = 0;
  long count = 1;
  double timeout_s = 30;
  // --rx-times (no value): print "rx <header.stamp ns> <take time ns>"
  // (CLOCK_REALTIME) per cloud instead of its digest line, for
  // scripts/bench-delivery.sh.
  bool rx_times = false;
};

inline SubscriberArgs parseSubscriberArgs(int argc, char** argv) {
  SubscriberArgs a;
  auto bad = [&](const std::string& why) {
    std::fprintf(stderr, "%s: %s\nusage: %s --topic NAME [--domain N] [--count N] [--timeout S]\n",
                 argv[0], why.c_str(), argv[0]);
    std::exit(2);
  };
  for (int i = 1; i < argc; ++i) {
    const std::string opt = argv[i];
    if (opt == "--rx-times") {
      a.rx_times = true;
      continue;
    }
    if (i + 1 >= argc) bad(opt + " needs a value");
    const std::string value = argv[++i];
    char* end = nullptr;
    if (opt == "--topic") {
      a.topic = value;
    } else if (opt == "--domain") {
      a.domain = static_cast<int>(std::strtol(value.c_str(), &end, 10));
      if (*end != '\0' || a.domain < 0 || a.domain > 232) bad("--domain: expected 0..232");
    } else if (opt == "--count") {
      a.count = std::strtol(value.c_str(), &end, 10);
      if (*end != '\0' || a.count < 1) bad("--count: expected a positive integer");
    } else if (opt == "--timeout") {
      a.timeout_s = std::strtod(value.c_str(), &end);
      if (*end != '\0' || !(a.timeout_s > 0)) bad("--timeout: expected seconds > 0");
    } else {
      bad("unknown option " + opt);
    }
  }
  if (a.topic.empty()) bad("--topic is required");
  return a;
}

}  // namespace sl::interop
