// cyclone_points_subscriber: the reference side of the interop test. A Cyclone
// DDS subscriber with the daemon's own types (idl/ via idlc) that prints the
// same digestLine() as fastdds_points_subscriber, so the test can check that
// Fast DDS decoded exactly what the daemon published.
// Usage and output: see subscriber_args.h and cloud_digest.h.
#include <chrono>
#include <cstdio>

#include "cloud_digest.h"
#include "sensor_msgs/msg/PointCloud2.h"
#include "sl/dds/dds.h"
#include "subscriber_args.h"

namespace {

using Cloud = sensor_msgs_msg_dds__PointCloud2_;

sl::interop::CloudInfo describe(const Cloud& m) {
  sl::interop::CloudInfo c;
  c.stamp_sec = m.header.stamp.sec;
  c.stamp_nanosec = m.header.stamp.nanosec;
  c.frame_id = m.header.frame_id ? m.header.frame_id : "";
  c.height = m.height;
  c.width = m.width;
  for (std::uint32_t i = 0; i < m.fields._length; ++i) {
    const auto& f = m.fields._buffer[i];
    c.fields.push_back({f.name ? f.name : "", f.offset, f.datatype, f.count});
  }
  c.is_bigendian = m.is_bigendian;
  c.point_step = m.point_step;
  c.row_step = m.row_step;
  c.data = m.data._buffer;
  c.data_size = m.data._length;
  c.is_dense = m.is_dense;
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  const sl::interop::SubscriberArgs args = sl::interop::parseSubscriberArgs(argc, argv);
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(args.timeout_s);
  try {
    namespace dds = sl::dds;
    dds::Participant participant(static_cast<dds_domainid_t>(args.domain));
    dds::Topic<Cloud> topic(participant, args.topic, sensor_msgs_msg_dds__PointCloud2__desc);
    dds::Reader<Cloud> reader(participant, topic, dds::Qos().reliable().keepLast(4));
    dds::ReadCondition has_data(reader);
    dds::WaitSet waitset(participant);
    waitset.attach(has_data);

    bool ready = false;
    long received = 0;
    while (received < args.count) {
      const auto now = std::chrono::steady_clock::now();
      if (now >= deadline) {
        std::fprintf(stderr,
                     "cyclone_points_subscriber: timeout: %s, %ld of %ld clouds on \"%s\" "
                     "within %.1f s\n",
                     ready ? "writer matched" : "no writer matched", received, args.count,
                     args.topic.c_str(), args.timeout_s);
        return 1;
      }
      if (!ready) {
        if (reader.waitForWriters(1, DDS_MSECS(20))) {
          ready = true;
          std::printf("ready: %u writer(s) matched on %s\n", reader.matchedWriters(),
                      args.topic.c_str());
          std::fflush(stdout);
        }
        continue;
      }
      if (!waitset.wait(DDS_MSECS(200))) continue;
      dds::Loan<Cloud> loan = reader.take(4);
      for (std::size_t i = 0; i < loan.size() && received < args.count; ++i) {
        if (!loan.isValid(i)) continue;
        ++received;
        std::printf("%s\n", sl::interop::digestLine(describe(loan[i])).c_str());
        std::fflush(stdout);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cyclone_points_subscriber: %s\n", e.what());
    return 2;
  }
  return 0;
}
