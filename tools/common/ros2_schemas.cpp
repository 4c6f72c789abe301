#include "ros2_schemas.h"

#include <map>
#include <stdexcept>

namespace sl::tools {

namespace {

const char* const kSeparator =
    "================================================================================\n";

// Field lists, one type each (the standard ROS 2 definitions, comments left out).
const std::map<std::string, std::string>& fieldLists() {
  static const std::map<std::string, std::string> lists = {
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
      // sl_msgs, from idl/sl_msgs/msg/*.idl (enums are uint32 on the wire).
      {"sl_msgs/Status",
       "uint32 STATE_IDLE=0\nuint32 STATE_SCANNING=1\nuint32 STATE_ERROR=2\n"
       "uint32 STATE_WAITING=3\nuint32 STATE_DEGRADED=4\nuint32 TRIGGER_DEFAULT=0\nuint32 TRIGGER_HARDWARE=1\n"
       "uint32 TRIGGER_SOFTWARE=2\n"
       "builtin_interfaces/Time stamp\nuint32 state\nstring pattern\nuint64 scans_done\n"
       "uint64 scans_requested\nfloat64 scan_rate_hz\nuint64 frames_dropped\n"
       "uint64 sets_dropped\nuint64 sets_incomplete\nuint64 frames_overflow\n"
       "uint64 frames_unmatched\nuint64 sets_overflow\nuint64 writes_timed_out\n"
       "uint64 sets_not_recorded\nstring recording\nuint64 sets_recorded\nstring last_error\n"
       "string[] patterns\nuint32 trigger\nstring[] cameras\nbool motion_compensation\n"
       "builtin_interfaces/Time start_at\nfloat64 frame_rate_hz\nuint64 requests_received\n"
       "uint64 requests_answered\nuint64 requests_rate_limited\nuint64 requests_invalid\n"
       "uint64 replies_timed_out\nstring degraded_reason\nbuiltin_interfaces/Time last_error_stamp\n"
       "uint64 errors_reported\nuint64 requests_malformed\nuint64 sets_over_quota\n"
       "float64 latency_ms\nfloat64 latency_max_ms\nfloat64 wait_ms\nfloat64 processing_ms\n"
       "float64 publish_ms\n"
       "uint64 requests_rejected\nuint64 clouds_lost_to_readers\n"
       "sl_msgs/PointsReader[] points_readers\n"},
      {"sl_msgs/PointsReader",
       "string guid\nbool reliable\nbool acknowledging\nuint64 clouds_lost\n"},
      {"sl_msgs/ImageSet",
       "std_msgs/Header header\nstring pattern\nuint64 sequence_id\nuint32 camera_count\n"
       "string[] camera_ids\nuint8[] bit_depths\nsensor_msgs/Image[] images\n"},
      {"sl_msgs/ProjectorMaps",
       "std_msgs/Header header\nstring pattern\nuint64 scan_index\nuint32 height\n"
       "uint32 width\nfloat32[] up\nfloat32[] vp\nfloat32[] modulation\nuint8[] status\n"},
  };
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
