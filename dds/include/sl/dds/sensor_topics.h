// The sensor's participant and topic set, declared once: the daemon's bridge
// (which writes clouds, maps, images and status, reads requests, writes
// replies) and SensorClient (which writes requests, reads replies, status
// and clouds) both create it. A topic is a local entity: creating one this
// process does not read or write costs no discovery traffic.
//
// Thread-compatible, like the dds:: wrappers it holds. Not movable: readers
// and writers refer to its participant and topics.
#pragma once

#include <string>

#include "sl/dds/dds.h"
#include "sl/dds/msg_convert.h"
#include "sl/dds/topic_names.h"

namespace sl::dds {

struct SensorTopics {
  // Throws sl::dds::Error naming the failing call.
  SensorTopics(int domain_id, const std::string& ns);
  SensorTopics(const SensorTopics&) = delete;
  SensorTopics& operator=(const SensorTopics&) = delete;

  const TopicNames names;
  Participant participant;
  Topic<msg::PointCloud2> points;
  Topic<msg::Maps> projector_maps;
  Topic<msg::ImageSetMsg> image_sets;
  Topic<msg::Status> status;
  Topic<msg::Request> request;
  Topic<msg::Reply> reply;
  Topic<msg::Image> depth_image;
  Topic<msg::Image> shading_image;
  Topic<msg::CameraInfo> camera_info;
};

}  // namespace sl::dds
