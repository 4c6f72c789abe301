// The daemon's DDS edge: owns the DDS entities and decides what is published
// (which topics exist, frame ids, camera_info) and what the engine's results
// must carry for it. The samples are built by ros_messages.h, requests
// carried out by request_dispatch.h (both private to daemon/, without DDS
// entities). Only daemon/ meets the IDL types.
//
// Topics (ns = DdsConfig::ns, default "sl"):
//   rt/<ns>/points          sensor_msgs/PointCloud2 (ROS 2 wire format, XCDR1)
//   rt/<ns>/projector_maps  sl_msgs ProjectorMaps (when enabled)
//   rt/<ns>/depth/image     sensor_msgs/Image 32FC1, metres, raw pixel grid (when publish_images)
//   rt/<ns>/depth/image_rect  the same on the rectified grid (first camera; when publish_images)
//   rt/<ns>/depth/camera_info sensor_msgs/CameraInfo of depth/image_rect: D = 0, P = [K | 0]
//   rt/<ns>/shading/image   sensor_msgs/Image mono8, the fringe offset A (when publish_images)
//   rt/<ns>/shading/camera_info, rt/<ns>/camera_info  sensor_msgs/CameraInfo of the raw
//                           images of the triangulating camera (when publish_images)
//   rt/<ns>/shading/image/compressed, rt/<ns>/depth/image_rect/compressedDepth
//                           sensor_msgs/CompressedImage in image_transport's formats,
//                           encoded only while a reader is matched (when publish_images)
//   rt/<ns>/status          sl_msgs Status (transient-local)
//   rq/<ns>/commandRequest  sl_msgs CommandRequest (from clients)
//   rr/<ns>/commandReply    sl_msgs CommandReply (one per request)
//   rt/<adaptive.velocity_topic>  geometry_msgs/TwistStamped, read (adaptive scanning)
//   rt/tf_static            tf2_msgs/TFMessage, the sensor's frames (dds.tf)
//   rt/diagnostics          diagnostic_msgs/DiagnosticArray, 1 Hz
//   ros_discovery_info      rmw_dds_common/ParticipantEntitiesInfo: node /<ns>/sl_sensord
#pragma once

#include <map>
#include <memory>
#include <string>

#include "sl/daemon/config.h"
#include "sl/daemon/scan_engine.h"
#include "sl/dds/topic_names.h"
#include "sl/pipeline/camera_model.h"

namespace sl::daemon {

// ROS frame ids of the clouds and images: dds.frame_id for the first camera,
// "<camera id>_optical_frame" for the others. camera_info is published for
// the first camera only (the bridge has its model).
struct FrameIds {
  std::string first_camera_id;
  std::string first_frame_id;
  std::string of(const std::string& camera_id) const;
  bool isFirst(const std::string& camera_id) const;
};

// Thread-safe in the way the daemon uses it: publish() from the engine's
// output thread while serve() runs on another; stop() from any thread.
class DdsBridge {
 public:
  // Creates the participant, topics, writers and the request reader; throws
  // sl::dds::Error naming the failing call.
  // `camera_id`, `calibration`: the first camera (frame dds.frame_id) and its
  // calibration (camera_info, /tf_static); `other_cameras`: the further
  // cameras' calibrations by camera id (/tf_static, /diagnostics). Throws
  // ConfigError when the dds.tf frames collide.
  DdsBridge(const DdsConfig& config, const std::string& camera_id,
            const pipeline::CameraProjectorCalibration& calibration,
            const std::map<std::string, pipeline::CameraProjectorCalibration>& other_cameras = {});
  ~DdsBridge();

  // What the engine's results must carry for the configured topics: clouds
  // in metres, projector maps when dds.publish_projector_maps.
  ResultContents resultContents() const;
  // Writes the result's cloud and, as configured, its image set, projector
  // maps, depth/shading images and camera_info. Writes that time out are
  // counted (status writes_timed_out).
  void publish(const ScanResult& result);

  // Answers requests and publishes status (on change and every
  // status_period_s) until stop(). Blocks.
  void serve(ScanEngine& engine);
  void stop();
  void setStatusPeriod(double seconds);  // any thread

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::daemon
