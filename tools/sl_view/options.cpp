#include "options.h"

#include <stdexcept>

#include "common/cli.h"

namespace sl::view {

std::string ArgCursor::value() {
  if (i_ + 1 >= argc_) throw std::invalid_argument(option() + " needs a value");
  ++i_;
  return argv_[i_];
}

int ArgCursor::integer(int lo, int hi) {
  const std::string name = option();
  const std::string v = value();
  const auto n = tools::toInt(v);
  if (!n || *n < lo || *n > hi)
    throw std::invalid_argument(name + " " + v + ": expected an integer in [" +
                                std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return *n;
}

double ArgCursor::positive() {
  const std::string name = option();
  const std::string v = value();
  const auto s = tools::toNumber(v);
  if (!s || !(*s > 0)) throw std::invalid_argument(name + " " + v + ": expected a number > 0");
  return *s;
}

bool parseTopicOption(ArgCursor& args, RawTopicsOptions& topics) {
  const std::string a = args.option();
  if (a == "--domain") topics.domain_id = args.integer(0, 232);
  else if (a == "--ns") topics.ns = args.value();
  else if (a == "--best-effort") topics.best_effort = true;
  else if (a == "--reliable") topics.best_effort = false;
  else return false;
  return true;
}

client::ClientOptions clientOptions(const RawTopicsOptions& topics) {
  client::ClientOptions co;
  co.domain_id = topics.domain_id;
  co.ns = topics.ns;
  co.subscribe_points = false;
  return co;
}

}  // namespace sl::view
