// The sensor's DDS topic names for one namespace (DdsConfig::ns, default
// "sl"), the one place they are spelled; see docs/interface.md "Topics".
//   rt/<ns>/points          sensor_msgs/PointCloud2
//   rt/<ns>/projector_maps  sl_msgs ProjectorMaps
//   rt/<ns>/image_sets      sl_msgs ImageSet
//   rt/<ns>/status          sl_msgs Status (transient-local)
//   rq/<ns>/commandRequest  sl_msgs CommandRequest (from clients)
//   rr/<ns>/commandReply    sl_msgs CommandReply (one per request)
//   rt/<ns>/depth/image, rt/<ns>/shading/image, rt/<ns>/camera_info
//   rt/<ns>/depth/image_rect, rt/<ns>/depth/camera_info, rt/<ns>/shading/camera_info
//   rt/<ns>/shading/image/compressed, rt/<ns>/depth/image_rect/compressedDepth
// (the global graph topics rt/tf_static, rt/diagnostics, ros_discovery_info
// are not per namespace: daemon/src/ros_graph.h)
#pragma once

#include <string>

namespace sl::dds {

struct TopicNames {
  std::string points, projector_maps, image_sets, status, request, reply;
  std::string depth_image, shading_image, camera_info;
  std::string depth_image_rect, depth_camera_info, shading_camera_info;
  std::string shading_compressed, depth_rect_compressed_depth;
  static TopicNames forNamespace(const std::string& ns);
};

}  // namespace sl::dds
