/* A forger of clouds (dds_security): a participant, without security unless
 * CYCLONEDDS_URI gives it some, that publishes small PointCloud2 samples
 * with frame_id "forged" on a sensor's points topic, as an attacker on the
 * network would. Waits up to 3 s for a matching reader (none is not an
 * error: a protected topic matches no unauthenticated writer), then writes
 * COUNT clouds PERIOD_MS apart (reliable, keep-last 1) and prints how many
 * it wrote and how many readers matched. The test decides from what the
 * readers took. Exit 0 when every write returned OK, 1 on a DDS failure,
 * 2 on bad arguments.
 * Usage: forged_points TOPIC COUNT PERIOD_MS */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <dds/dds.h>

#include "sensor_msgs/msg/PointCloud2.h"

static int fail(const char* call, dds_return_t rc) {
  fprintf(stderr, "forged_points: %s failed: %s\n", call, dds_strretcode(rc));
  return 1;
}

int main(int argc, char** argv) {
  if (argc != 4 || atoi(argv[2]) < 1 || atoi(argv[3]) < 0) {
    fprintf(stderr, "usage: forged_points TOPIC COUNT PERIOD_MS\n");
    return 2;
  }
  const char* topic_name = argv[1];
  const int count = atoi(argv[2]);
  const int period_ms = atoi(argv[3]);
  const dds_entity_t participant = dds_create_participant(DDS_DOMAIN_DEFAULT, NULL, NULL);
  if (participant < 0) return fail("dds_create_participant", participant);
  const dds_entity_t topic =
      dds_create_topic(participant, &sensor_msgs_msg_dds__PointCloud2__desc, topic_name, NULL, NULL);
  if (topic < 0) return fail("dds_create_topic", topic);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  const dds_entity_t writer = dds_create_writer(participant, topic, qos, NULL);
  dds_delete_qos(qos);
  if (writer < 0) return fail("dds_create_writer", writer);

  dds_publication_matched_status_t matched = {0};
  for (int i = 0; i < 60 && matched.current_count == 0; ++i) {
    dds_get_publication_matched_status(writer, &matched);
    if (matched.current_count == 0) dds_sleepfor(DDS_MSECS(50));
  }

  /* 2 x 2 points of x, y, z float32 at z = 1 m. */
  static char x[] = "x", y[] = "y", z[] = "z", frame[] = "forged";
  sensor_msgs_msg_dds__PointField_ fields[3] = {
      {x, 0, sensor_msgs_msg_dds__PointField_Constants_FLOAT32, 1},
      {y, 4, sensor_msgs_msg_dds__PointField_Constants_FLOAT32, 1},
      {z, 8, sensor_msgs_msg_dds__PointField_Constants_FLOAT32, 1}};
  float points[4][3] = {{0, 0, 1}, {0.1f, 0, 1}, {0, 0.1f, 1}, {0.1f, 0.1f, 1}};
  sensor_msgs_msg_dds__PointCloud2_ cloud;
  memset(&cloud, 0, sizeof cloud);
  cloud.header.frame_id = frame;
  cloud.height = 2;
  cloud.width = 2;
  cloud.fields._buffer = fields;
  cloud.fields._length = cloud.fields._maximum = 3;
  cloud.point_step = 12;
  cloud.row_step = 24;
  cloud.data._buffer = (uint8_t*)points;
  cloud.data._length = cloud.data._maximum = sizeof points;
  cloud.is_dense = 1;

  int written = 0;
  for (int i = 0; i < count; ++i) {
    cloud.header.stamp.sec = i;
    const dds_return_t rc = dds_write(writer, &cloud);
    if (rc != DDS_RETCODE_OK) return fail("dds_write", rc);
    ++written;
    dds_sleepfor(DDS_MSECS(period_ms));
  }
  dds_get_publication_matched_status(writer, &matched);
  printf("forged_points: wrote %d clouds to %s; readers matched: %d\n", written, topic_name,
         (int)matched.current_count);
  dds_delete(participant);
  return 0;
}
