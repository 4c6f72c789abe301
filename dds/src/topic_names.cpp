#include "sl/dds/topic_names.h"

namespace sl::dds {

TopicNames TopicNames::forNamespace(const std::string& ns) {
  return {"rt/" + ns + "/points", "rt/" + ns + "/projector_maps", "rt/" + ns + "/image_sets",
          "rt/" + ns + "/status", "rq/" + ns + "/commandRequest", "rr/" + ns + "/commandReply",
          "rt/" + ns + "/depth/image", "rt/" + ns + "/shading/image", "rt/" + ns + "/camera_info",
          "rt/" + ns + "/depth/image_rect", "rt/" + ns + "/depth/camera_info",
          "rt/" + ns + "/shading/camera_info", "rt/" + ns + "/shading/image/compressed",
          "rt/" + ns + "/depth/image_rect/compressedDepth"};
}

}  // namespace sl::dds
