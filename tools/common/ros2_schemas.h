// ROS 2 message definitions (the `ros2msg` schema encoding of MCAP and the
// Foxglove WebSocket protocol) of the types the daemon publishes: the main
// type's fields, then every type it uses after a separator line and
// "MSG: package/Type". sl_msgs's are ros2/sl_msgs/msg/*.msg without comments.
#pragma once

#include <string>
#include <vector>

namespace sl::tools {

struct Ros2Schema {
  std::string name;        // "sensor_msgs/msg/PointCloud2"
  std::string definition;  // ros2msg text
};

// The schema of a ROS 2 type name; throws std::invalid_argument naming it
// if it is not one of the daemon's types.
const Ros2Schema& ros2Schema(const std::string& type_name);

}  // namespace sl::tools
