#include "ros2_schemas.h"

#include <map>
#include <stdexcept>

#include "sl_msgs/ros2_definitions.h"

namespace sl::tools {

namespace {

const char* const kSeparator =
    "================================================================================\n";

// Field lists, one type each (the standard ROS 2 definitions, comments left out).
const std::map<std::string, std::string>& fieldLists() {
  static const std::map<std::string, std::string> lists = [] {
    std::map<std::string, std::string> m = {
      {"builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"},
      {"std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n"},
      {"sensor_msgs/PointField",
       "uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\n"
       "uint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\n"
       "string name\nuint32 offset\nuint8 datatype\nuint32 count\n"},
      {"sensor_msgs/PointCloud2",
       "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\n"
       "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n"},
      {"sensor_msgs/Image",
       "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
       "uint8 is_bigendian\nuint32 step\nuint8[] data\n"},
      {"sensor_msgs/RegionOfInterest",
       "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"},
      {"sensor_msgs/CameraInfo",
       "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
       "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
       "uint32 binning_y\nsensor_msgs/RegionOfInterest roi\n"},
    };
    // sl_msgs: generated from ros2/sl_msgs/msg/*.msg (idl/CMakeLists.txt).
    for (const auto& d : sl_msgs_definitions::kMessages) m.emplace(d.type, d.fields);
    return m;
  }();
  return lists;
}

// The types a type's fields name, depth-first, each once.
void dependencies(const std::string& type, std::vector<std::string>& out) {
  const std::string& fields = fieldLists().at(type);
  std::size_t line = 0;
  while (line < fields.size()) {
    const std::size_t end = fields.find('\n', line);
    std::string field_type = fields.substr(line, fields.find(' ', line) - line);
    line = end + 1;
    if (const auto bracket = field_type.find('['); bracket != std::string::npos)
      field_type.resize(bracket);
    if (field_type.find('/') == std::string::npos) continue;
    bool seen = false;
    for (const auto& t : out) seen = seen || t == field_type;
    if (seen) continue;
    out.push_back(field_type);
    dependencies(field_type, out);
  }
}

Ros2Schema build(const std::string& short_name) {
  Ros2Schema schema;
  const auto slash = short_name.find('/');
  schema.name = short_name.substr(0, slash) + "/msg" + short_name.substr(slash);
  schema.definition = fieldLists().at(short_name);
  std::vector<std::string> deps;
  dependencies(short_name, deps);
  for (const auto& dep : deps)
    schema.definition += kSeparator + std::string("MSG: ") + dep + "\n" + fieldLists().at(dep);
  return schema;
}

}  // namespace

const Ros2Schema& ros2Schema(const std::string& type_name) {
  static const std::map<std::string, Ros2Schema> schemas = [] {
    std::map<std::string, Ros2Schema> m;
    for (const char* t : {"sensor_msgs/PointCloud2", "sensor_msgs/Image", "sensor_msgs/CameraInfo",
                          "sl_msgs/Status", "sl_msgs/ImageSet", "sl_msgs/ProjectorMaps"}) {
      Ros2Schema s = build(t);
      m.emplace(s.name, std::move(s));
    }
    return m;
  }();
  const auto it = schemas.find(type_name);
  if (it == schemas.end())
    throw std::invalid_argument("no ROS 2 schema for type '" + type_name + "'");
  return it->second;
}

}  // namespace sl::tools
