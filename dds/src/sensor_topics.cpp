#include "sl/dds/sensor_topics.h"

namespace sl::dds {

SensorTopics::SensorTopics(int domain_id, const std::string& ns)
    : names(TopicNames::forNamespace(ns)),
      participant(domain_id),
      points(participant, names.points, sensor_msgs_msg_dds__PointCloud2__desc),
      projector_maps(participant, names.projector_maps, sl_msgs_msg_dds__ProjectorMaps__desc),
      image_sets(participant, names.image_sets, sl_msgs_msg_dds__ImageSet__desc),
      status(participant, names.status, sl_msgs_msg_dds__Status__desc),
      request(participant, names.request, sl_msgs_msg_dds__CommandRequest__desc),
      reply(participant, names.reply, sl_msgs_msg_dds__CommandReply__desc),
      depth_image(participant, names.depth_image, sensor_msgs_msg_dds__Image__desc),
      shading_image(participant, names.shading_image, sensor_msgs_msg_dds__Image__desc),
      camera_info(participant, names.camera_info, sensor_msgs_msg_dds__CameraInfo__desc) {}

}  // namespace sl::dds
