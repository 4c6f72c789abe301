// Command-line parsing shared by sl_view's modes (live view, record, play):
// one cursor over argv, the options every mode takes (DDS domain, namespace,
// reader reliability) and the daemon client built from them.
//
// Errors throw std::invalid_argument naming the option and the value (main
// prints the usage and exits 2).
#pragma once

#include <string>

#include "raw_topics.h"
#include "sl/client/client.h"

namespace sl::view {

class ArgCursor {
 public:
  // Walks argv[first..argc).
  ArgCursor(int argc, char** argv, int first) : argc_(argc), argv_(argv), i_(first - 1) {}

  // Moves to the next argument; false past the last.
  bool next() { return ++i_ < argc_; }
  std::string option() const { return argv_[i_]; }
  // The current option's value (the next argument).
  std::string value();
  int integer(int lo, int hi);
  double positive();  // a number > 0

 private:
  int argc_;
  char** argv_;
  int i_;
};

// --domain N, --ns NAME, --best-effort, --reliable: applied to `topics` and
// true if the current option is one of them.
bool parseTopicOption(ArgCursor& args, RawTopicsOptions& topics);

// A daemon client on the same domain and namespace, not reading clouds.
client::ClientOptions clientOptions(const RawTopicsOptions& topics);

}  // namespace sl::view
