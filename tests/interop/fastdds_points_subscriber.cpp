// fastdds_points_subscriber: an eProsima Fast DDS subscriber to a ROS 2
// sensor_msgs/msg/PointCloud2 topic, as a ROS 2 node on rmw_fastrtps would
// be. Its types come from ros2_idl/ through fastddsgen (nothing from the
// daemon's idl/), so receiving the daemon's clouds here shows that the wire
// format, the type name and the QoS match what ROS 2 expects.
//
// Fast DDS is configured from the XML file in FASTRTPS_DEFAULT_PROFILES_FILE
// (as for any Fast DDS / ROS 2 program), e.g. config/fastdds-loopback.xml.
// Usage and output: see subscriber_args.h and cloud_digest.h.
#include <chrono>
#include <cstdio>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <thread>

#include "PointCloud2PubSubTypes.h"
#include "cloud_digest.h"
#include "subscriber_args.h"

namespace {

namespace fdds = eprosima::fastdds::dds;
using Cloud = sensor_msgs::msg::dds_::PointCloud2_;

sl::interop::CloudInfo describe(const Cloud& m) {
  sl::interop::CloudInfo c;
  c.stamp_sec = m.header().stamp().sec();
  c.stamp_nanosec = m.header().stamp().nanosec();
  c.frame_id = m.header().frame_id();
  c.height = m.height();
  c.width = m.width();
  for (const auto& f : m.fields())
    c.fields.push_back({f.name(), f.offset(), f.datatype(), f.count()});
  c.is_bigendian = m.is_bigendian();
  c.point_step = m.point_step();
  c.row_step = m.row_step();
  c.data = m.data().data();
  c.data_size = m.data().size();
  c.is_dense = m.is_dense();
  return c;
}

// Deletes everything the participant created, and the participant.
struct ParticipantGuard {
  fdds::DomainParticipant* p = nullptr;
  ~ParticipantGuard() {
    if (p) {
      p->delete_contained_entities();
      fdds::DomainParticipantFactory::get_instance()->delete_participant(p);
    }
  }
};

}  // namespace

int main(int argc, char** argv) {
  const sl::interop::SubscriberArgs args = sl::interop::parseSubscriberArgs(argc, argv);
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(args.timeout_s);
  auto fail = [](const char* what) {
    std::fprintf(stderr, "fastdds_points_subscriber: %s failed\n", what);
    return 2;
  };

  auto* factory = fdds::DomainParticipantFactory::get_instance();
  ParticipantGuard guard;
  guard.p = factory->create_participant(args.domain, fdds::PARTICIPANT_QOS_DEFAULT);
  if (!guard.p) return fail("create_participant");
  fdds::TypeSupport type(new sensor_msgs::msg::dds_::PointCloud2_PubSubType());
  if (type.register_type(guard.p) != ReturnCode_t::RETCODE_OK) return fail("register_type");
  fdds::Topic* topic =
      guard.p->create_topic(args.topic, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
  if (!topic) return fail("create_topic");
  fdds::Subscriber* subscriber = guard.p->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  if (!subscriber) return fail("create_subscriber");

  // ROS 2's default subscription QoS (reliable, volatile, keep-last), and
  // sample buffers that grow to the 25 MB clouds: the preallocated size
  // fastddsgen computes assumes sequences of 100 elements.
  fdds::DataReaderQos qos = subscriber->get_default_datareader_qos();
  qos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  qos.durability().kind = fdds::VOLATILE_DURABILITY_QOS;
  qos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  qos.history().depth = 4;
  qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;
  fdds::DataReader* reader = subscriber->create_datareader(topic, qos);
  if (!reader) return fail("create_datareader");

  bool ready = false;
  long received = 0;
  Cloud cloud;
  while (received < args.count) {
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) {
      std::fprintf(stderr,
                   "fastdds_points_subscriber: timeout: %s, %ld of %ld clouds on \"%s\" within "
                   "%.1f s\n",
                   ready ? "writer matched" : "no writer matched", received, args.count,
                   args.topic.c_str(), args.timeout_s);
      return 1;
    }
    if (!ready) {
      fdds::SubscriptionMatchedStatus matched;
      reader->get_subscription_matched_status(matched);
      if (matched.current_count > 0) {
        ready = true;
        std::printf("ready: %d writer(s) matched on %s\n", matched.current_count,
                    args.topic.c_str());
        std::fflush(stdout);
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        continue;
      }
    }
    const double left_s = std::chrono::duration<double>(deadline - now).count();
    if (!reader->wait_for_unread_message(eprosima::fastrtps::Duration_t(std::min(left_s, 0.2))))
      continue;
    fdds::SampleInfo info;
    while (received < args.count &&
           reader->take_next_sample(&cloud, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      ++received;
      if (args.rx_times) {
        const long long now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                  std::chrono::system_clock::now().time_since_epoch())
                                  .count();
        std::printf("rx %lld %lld\n",
                    static_cast<long long>(cloud.header().stamp().sec()) * 1000000000LL +
                        cloud.header().stamp().nanosec(),
                    now);
        continue;
      }
      std::printf("%s\n", sl::interop::digestLine(describe(cloud)).c_str());
      std::fflush(stdout);
    }
  }
  return 0;
}
