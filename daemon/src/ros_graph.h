// The daemon in ROS 2's graph (docs/ros2.md "tf", "Diagnostics", "The node
// graph"): /tf_static, /diagnostics and ros_discovery_info, written as ROS 2
// nodes write them. DdsBridge owns one of each.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <dds/dds.h>

#include "reader_acks.h"    // MatchedReaderState
#include "request_guard.h"  // RequestCounters
#include "sl/dds/dds.h"
#include "sl/daemon/scan_engine.h"
#include "tf_tree.h"

#include "diagnostic_msgs/msg/DiagnosticArray.h"
#include "rmw_dds_common/msg/ParticipantEntitiesInfo.h"
#include "tf2_msgs/msg/TFMessage.h"

namespace sl::daemon {

// rt/tf_static, tf2_msgs/msg/TFMessage, reliable + transient-local + keep-last
// 1 as tf2_ros's StaticTransformBroadcaster has it: all of the sensor's
// transforms in one message, written once at construction (late joiners get
// it from the writer's history).
class TfStaticPublisher {
 public:
  TfStaticPublisher(const dds::Participant& participant, const std::vector<FrameTransform>& transforms,
                    std::int64_t stamp_ns);
  dds_entity_t writer() const { return writer_.handle(); }

 private:
  dds::Topic<tf2_msgs_msg_dds__TFMessage_> topic_;
  dds::Writer<tf2_msgs_msg_dds__TFMessage_> writer_;
};

// One diagnostic_msgs/DiagnosticStatus before it becomes a sample.
struct Diagnostic {
  std::uint8_t level = 0;  // OK 0, WARN 1, ERROR 2, STALE 3
  std::string name, message, hardware_id;
  std::vector<std::pair<std::string, std::string>> values;
};

// What /diagnostics reports besides the engine's status.
struct DiagnosticInputs {
  std::string node_name;                 // status names are "<node_name>: <part>"
  std::vector<std::string> camera_ids;   // every camera of the sensor
  RequestCounters requests;
  std::uint64_t writes_timed_out = 0;
  std::uint64_t images_not_compressed = 0;
  std::uint64_t clouds_lost_to_readers = 0;
  std::vector<MatchedReaderState> points_readers;
};

// One status per camera, one for the trigger source and one for the
// pipeline, levels from the daemon's state: idle / waiting / scanning OK;
// degraded WARN on the pipeline and on each device its cause names (the
// cause's parts "camera '<id>': ..." and "trigger source: ..."); error ERROR
// on the pipeline with the last error. A device whose error is the last
// error (it starts "camera '<id>'" / "trigger source") is ERROR until the
// engine clears it. A points reader that lost clouds makes the pipeline WARN
// when it would be OK.
std::vector<Diagnostic> diagnosticsOf(const EngineStatus& status, const DiagnosticInputs& inputs);

// rt/diagnostics, diagnostic_msgs/msg/DiagnosticArray (reliable, volatile,
// keep-last 1, as diagnostic_updater creates its publisher: depth 1).
class DiagnosticsPublisher {
 public:
  explicit DiagnosticsPublisher(const dds::Participant& participant);
  bool publish(const std::vector<Diagnostic>& statuses, std::int64_t stamp_ns);
  dds_entity_t writer() const { return writer_.handle(); }

 private:
  dds::Topic<diagnostic_msgs_msg_dds__DiagnosticArray_> topic_;
  dds::Writer<diagnostic_msgs_msg_dds__DiagnosticArray_> writer_;
};

// ros_discovery_info (DDS topic name without "rt/": rmw creates it with
// avoid_ros_namespace_conventions), rmw_dds_common/msg/ParticipantEntitiesInfo
// as rmw_cyclonedds (Humble) writes it: reliable, transient-local, keep-last
// 1; gid = the participant's 16-byte GUID and 8 zero bytes; one node with the
// gids of every reader and writer of the participant but this one (rmw does
// not list its own ros_discovery_info endpoints either).
class DiscoveryInfoPublisher {
 public:
  DiscoveryInfoPublisher(const dds::Participant& participant, std::string node_namespace,
                         std::string node_name);
  // Lists the participant's readers and writers now and writes the sample.
  void publish();
  dds_entity_t writer() const { return writer_.handle(); }

 private:
  dds_entity_t participant_;
  std::string namespace_, name_;
  dds::Topic<rmw_dds_common_msg_dds__ParticipantEntitiesInfo_> topic_;
  dds::Writer<rmw_dds_common_msg_dds__ParticipantEntitiesInfo_> writer_;
};

}  // namespace sl::daemon
