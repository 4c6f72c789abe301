#include "request_origin.h"

namespace sl::daemon {

std::uint64_t RequestOrigins::senderOf(dds_entity_t reader, dds_instance_handle_t publication) {
  if (const auto it = participants_.find(publication); it != participants_.end()) return it->second;
  std::uint64_t sender = publication;
  if (dds_builtintopic_endpoint_t* writer = dds_get_matched_publication_data(reader, publication)) {
    if (writer->participant_instance_handle != 0) sender = writer->participant_instance_handle;
    dds_builtintopic_free_endpoint(writer);
    if (participants_.size() >= kMaxWriters) participants_.clear();
    participants_.emplace(publication, sender);  // only while matched: the handle is its writer's
  }
  return sender;
}

}  // namespace sl::daemon
