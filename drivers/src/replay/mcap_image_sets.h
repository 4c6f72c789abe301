// Image sets from an MCAP file (https://mcap.dev/spec) written by
// `sl_view record` while the daemon published rt/<ns>/image_sets: the
// sl_msgs/msg/ImageSet messages (CDR, XCDR1 little endian, as the daemon
// writes them) become the pipeline's ImageSets, equal to what a recording
// folder of the same sets gives.
//
// The file is read record by record from its start (chunks compressed with
// zstd or lz4, or not at all; chunk CRCs checked when set); it must be
// complete (footer and closing magic). Every size is checked against the
// file before anything is allocated. Errors are std::runtime_error naming
// the file and the record ("x.mcap: record 12 (chunk at byte 4096): ...").
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "sl/pipeline/types.h"

namespace sl::drivers {

// Immutable after construction; load() opens the file anew each call, so
// it is thread-safe.
class McapImageSets {
 public:
  // Reads the whole file once (decompressing every chunk) and keeps each
  // image set's metadata and position. Throws if the file is not a complete
  // MCAP file, is corrupt anywhere, or holds no image sets (named).
  explicit McapImageSets(const std::string& path);

  std::size_t size() const { return sets_.size(); }
  const pipeline::ImageSet& info(std::size_t i) const { return sets_.at(i).info; }
  pipeline::ImageSet load(std::size_t i) const;
  // "<file>: image set <k> (message <n>)" for messages about set i.
  std::string where(std::size_t i) const;
  const std::string& topic() const { return topic_; }

 private:
  struct Entry {
    pipeline::ImageSet info;       // frames empty
    std::uint64_t record_offset;   // file offset of the chunk or message record
    std::uint64_t inner_offset;    // message record within the chunk's records; 0 if not in a chunk
    bool in_chunk;
    std::uint64_t message_number;  // 1-based, over all messages of the file
  };
  std::string path_;
  std::string topic_;
  std::vector<Entry> sets_;
};

// Decodes one sl_msgs/msg/ImageSet CDR message (with its 4-byte
// encapsulation header). `what` names it in errors. With load_images false
// the frames stay empty (stamps, ids and depths are filled).
pipeline::ImageSet decodeImageSetCdr(std::string_view cdr, const std::string& what,
                                     bool load_images);

}  // namespace sl::drivers
