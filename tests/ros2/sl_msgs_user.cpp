// Compiled against the installed sl_msgs by build_sl_msgs.sh: the generated
// C++ types are usable by a downstream package (constants, nested types,
// service request/response).
#include <cstdio>

#include "sl_msgs/msg/status.hpp"
#include "sl_msgs/srv/get_config.hpp"
#include "sl_msgs/srv/list_patterns.hpp"
#include "sl_msgs/srv/set_pattern.hpp"
#include "sl_msgs/srv/start.hpp"

static_assert(sl_msgs::msg::Status::STATE_DEGRADED == 4);
static_assert(sl_msgs::srv::Start::Request::TRIGGER_SOFTWARE == 2);
static_assert(sl_msgs::srv::Start::Response::REPLY_UNSUPPORTED == 8);

int main() {
  sl_msgs::srv::Start::Request start;
  start.pattern = "3+3";
  start.count = 1;
  start.start_at.sec = 1;
  start.cameras.push_back("left");
  sl_msgs::msg::Status status;
  status.points_readers.emplace_back().clouds_lost = 3;
  sl_msgs::srv::ListPatterns::Response patterns;
  patterns.patterns.push_back("3+3");
  std::printf("%s %zu %zu\n", start.pattern.c_str(), status.points_readers.size(), patterns.patterns.size());
  return status.points_readers[0].clouds_lost == 3 ? 0 : 1;
}
