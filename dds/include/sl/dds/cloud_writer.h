// The writer of rt/<ns>/points. dds_write serializes a sample into a buffer
// of Cyclone's before sending it: for a 25 MB cloud that is one more 25 MB
// copy (docs/measurements.md) on the way from the triangulator to the socket. This
// writer hands Cyclone a serialized sample (a "serdata") whose point data is
// the cloud's own memory: the CDR bytes before the data (header, fields,
// the data's length) and after it (is_dense, padding) are its own, and the
// points are read in place when Cyclone fragments the sample. The sample
// keeps the cloud alive (a shared owner) until Cyclone lets go of it, after
// the last reader acknowledged it or the history dropped it.
//
// It checks, when created, that this works with the Cyclone DDS it runs on:
// a writer and a reader of the same topic in a private partition exchange a
// borrowed cloud, and the reader must get this writer's sample, unconverted,
// with the bytes dds_write would have sent. Where that fails, or shared
// memory (iceoryx) is configured (an iceoryx reader only receives what
// dds_write puts in shared memory), it writes with dds_write and says why.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/dds/dds.h"

namespace sl::dds {

class CloudWriter {
 public:
  using PointCloud2 = sensor_msgs_msg_dds__PointCloud2_;

  // A non-empty serialize_reason (e.g. "dds.points_zero_copy is false")
  // makes it always serialize, and is then whyNotBorrowing().
  CloudWriter(const dds::Participant& participant, const dds::Topic<PointCloud2>& topic,
              const dds::Qos& qos, std::string serialize_reason);
  ~CloudWriter();
  CloudWriter(const CloudWriter&) = delete;
  CloudWriter& operator=(const CloudWriter&) = delete;

  // Writes `sample`, whose data (sample.data._buffer, _length bytes) must
  // stay alive and unchanged as long as `owner` does (borrowed clouds keep
  // `owner`; serialized ones copy the data before this returns). Returns
  // false if a reliable write timed out; throws dds::Error for other failures.
  bool write(const PointCloud2& sample, std::shared_ptr<const void> owner);

  // True when clouds are sent from their own memory; else why not.
  bool borrowing() const;
  const std::string& whyNotBorrowing() const;

  dds_entity_t handle() const { return writer_.handle(); }

  // Copies of more than 1 MiB Cyclone asked of borrowed samples in this
  // process (a sample converted to another type, or taken by a reader of
  // another type in this process): 0 when every cloud went out borrowed.
  static std::uint64_t largeCopies();

  // The CDR bytes a borrowed sample of `sample` gives (for tests: they
  // must equal dds_write's); empty when this writer does not borrow.
  std::string borrowedBytes(const PointCloud2& sample) const;

 private:
  struct Borrowed;
  dds::Writer<PointCloud2> writer_;
  std::unique_ptr<Borrowed> borrowed_;  // null: serializing
  std::string why_not_;
};

}  // namespace sl::dds
