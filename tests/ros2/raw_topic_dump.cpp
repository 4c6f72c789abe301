// Takes the daemon's samples of some topics as serialized bytes (CDR, the
// 4-byte encapsulation first, as the daemon's writer produced them, not
// deserialized here) and writes each to a file, for a decoder that is not
// the project's own (Foxglove's ROS 2 deserializer in the .mjs checks).
//
// usage: raw_topic_dump OUT_DIR TIMEOUT_S COUNT NAME=DDS_TOPIC=TYPE...
//   TYPE: Image, CameraInfo, PointCloud2, CompressedImage (sensor_msgs/msg)
// Prints "ready" once every reader has matched a writer, then writes
// OUT_DIR/NAME_<k>.cdr (k = 1, 2, ...) until every topic gave COUNT
// samples (exit 0) or TIMEOUT_S passed (exit 1, the counts on stderr).
// OUT_DIR "-": counts the samples, writes no file (a reader for benchmarks).
// Readers: reliable, keep-all, volatile.
#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "sensor_msgs/msg/CameraInfo.h"
#include "sensor_msgs/msg/CompressedImage.h"
#include "sensor_msgs/msg/Image.h"
#include "sensor_msgs/msg/PointCloud2.h"

namespace {

const dds_topic_descriptor_t* descriptorOf(const std::string& type) {
  if (type == "Image") return &sensor_msgs_msg_dds__Image__desc;
  if (type == "CameraInfo") return &sensor_msgs_msg_dds__CameraInfo__desc;
  if (type == "PointCloud2") return &sensor_msgs_msg_dds__PointCloud2__desc;
  if (type == "CompressedImage") return &sensor_msgs_msg_dds__CompressedImage__desc;
  return nullptr;
}

struct Stream {
  std::string name;
  dds_entity_t reader = 0;
  int taken = 0;
};

int fail(const std::string& what) {
  std::fprintf(stderr, "raw_topic_dump: %s\n", what.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 5) return fail("usage: raw_topic_dump OUT_DIR TIMEOUT_S COUNT NAME=DDS_TOPIC=TYPE...");
  const std::string out = argv[1];
  const double timeout_s = std::atof(argv[2]);
  const int count = std::atoi(argv[3]);
  const dds_entity_t participant = dds_create_participant(DDS_DOMAIN_DEFAULT, nullptr, nullptr);
  if (participant < 0) return fail("dds_create_participant failed");
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  std::vector<Stream> streams;
  for (int i = 4; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto a = arg.find('='), b = arg.rfind('=');
    if (a == std::string::npos || a == b) return fail("argument '" + arg + "' is not NAME=DDS_TOPIC=TYPE");
    const dds_topic_descriptor_t* desc = descriptorOf(arg.substr(b + 1));
    if (desc == nullptr) return fail("unknown type in '" + arg + "'");
    const dds_entity_t topic = dds_create_topic(participant, desc, arg.substr(a + 1, b - a - 1).c_str(), nullptr, nullptr);
    if (topic < 0) return fail("dds_create_topic for '" + arg + "' failed");
    const dds_entity_t reader = dds_create_reader(participant, topic, qos, nullptr);
    if (reader < 0) return fail("dds_create_reader for '" + arg + "' failed");
    streams.push_back({arg.substr(0, a), reader, 0});
  }
  dds_delete_qos(qos);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (bool matched = false; !matched;) {
    matched = true;
    for (const Stream& s : streams) {
      dds_subscription_matched_status_t st{};
      dds_get_subscription_matched_status(s.reader, &st);
      matched = matched && st.current_count > 0;
    }
    if (std::chrono::steady_clock::now() > deadline) {
      std::fprintf(stderr, "raw_topic_dump: not every reader matched a writer within %.0f s\n", timeout_s);
      return 1;
    }
    if (!matched) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::printf("ready\n");
  std::fflush(stdout);
  for (;;) {
    bool done = true;
    for (Stream& s : streams) {
      for (;;) {
        ddsi_serdata* serdata = nullptr;
        dds_sample_info_t info;
        if (dds_takecdr(s.reader, &serdata, 1, &info, DDS_ANY_STATE) <= 0) break;
        if (info.valid_data) {
          const std::uint32_t size = ddsi_serdata_size(serdata);
          std::vector<char> bytes(size);
          ddsi_serdata_to_ser(serdata, 0, size, bytes.data());
          ++s.taken;
          if (out != "-")
            std::ofstream(out + "/" + s.name + "_" + std::to_string(s.taken) + ".cdr", std::ios::binary)
              .write(bytes.data(), static_cast<std::streamsize>(size));
        }
        ddsi_serdata_unref(serdata);
      }
      done = done && s.taken >= count;
    }
    if (done) break;
    if (std::chrono::steady_clock::now() > deadline) {
      for (const Stream& s : streams)
        std::fprintf(stderr, "raw_topic_dump: %s: %d of %d samples\n", s.name.c_str(), s.taken, count);
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  dds_delete(participant);
  return 0;
}
