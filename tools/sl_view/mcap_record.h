// `sl_view record FILE.mcap`: the daemon's topics, byte for byte as
// published, into an MCAP file with the ROS 2 profile.
#pragma once

#include <atomic>

namespace sl::view {

// argv[0] is "record". Returns the exit code (0 ok, 1 error, 2 usage,
// 3 no daemon, 4 scan request rejected, 5 a scan's image or camera_info
// missing from the file: named on stderr).
int recordMain(int argc, char** argv, const std::atomic<bool>& stop);

}  // namespace sl::view
