/* A subscriber of rt/<ns>/points in its own process (test_e2e "a points
 * reader that stops acknowledging ..."). Mode "read": reliable, keep-last 4,
 * takes every cloud. Mode "stuck": reliable, keep-all with room for one
 * cloud, never takes; Cyclone then refuses further clouds and does not
 * acknowledge them, as for a client that stopped reading. (In the test's own
 * process such a reader would hold back every reader of the process.)
 * Writes its reader's GUID, as Cyclone prints GUIDs, to GUID_FILE once
 * matched with the daemon's writer, then runs until killed. With TAKEN_FILE
 * (mode "read"), writes there the number of clouds taken so far after each
 * take.
 * Usage: points_subscriber NAMESPACE read|stuck GUID_FILE [TAKEN_FILE] */
#include <stdio.h>
#include <string.h>

#include <dds/dds.h>

#include "sensor_msgs/msg/PointCloud2.h"

static unsigned word(const dds_guid_t* g, int i) {
  return ((unsigned)g->v[4 * i] << 24) | ((unsigned)g->v[4 * i + 1] << 16) |
         ((unsigned)g->v[4 * i + 2] << 8) | (unsigned)g->v[4 * i + 3];
}

int main(int argc, char** argv) {
  if ((argc != 4 && argc != 5) ||
      (strcmp(argv[2], "read") != 0 && strcmp(argv[2], "stuck") != 0)) {
    fprintf(stderr, "usage: points_subscriber NAMESPACE read|stuck GUID_FILE [TAKEN_FILE]\n");
    return 2;
  }
  const int reads = strcmp(argv[2], "read") == 0;
  char topic_name[512];
  snprintf(topic_name, sizeof topic_name, "rt/%s/points", argv[1]);
  const dds_entity_t participant = dds_create_participant(DDS_DOMAIN_DEFAULT, NULL, NULL);
  if (participant < 0) return 1;
  const dds_entity_t topic = dds_create_topic(
      participant, &sensor_msgs_msg_dds__PointCloud2__desc, topic_name, NULL, NULL);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  if (reads) {
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 4);
  } else {
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
    dds_qset_resource_limits(qos, 1, DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
  }
  dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
  dds_qset_data_representation(qos, 1, &xcdr1);
  const dds_entity_t reader = dds_create_reader(participant, topic, qos, NULL);
  dds_delete_qos(qos);
  if (topic < 0 || reader < 0) return 1;
  dds_subscription_matched_status_t matched = {0};
  for (int i = 0; i < 400 && matched.current_count == 0; ++i) {
    dds_get_subscription_matched_status(reader, &matched);
    if (matched.current_count == 0) dds_sleepfor(DDS_MSECS(50));
  }
  if (matched.current_count == 0) {
    fprintf(stderr, "points_subscriber: no writer on %s\n", topic_name);
    return 1;
  }
  dds_guid_t guid;
  if (dds_get_guid(reader, &guid) != DDS_RETCODE_OK) return 1;
  FILE* f = fopen(argv[3], "w");
  if (!f) return 1;
  fprintf(f, "%x:%x:%x:%x\n", word(&guid, 0), word(&guid, 1), word(&guid, 2), word(&guid, 3));
  fclose(f);
  unsigned long long taken = 0;
  for (;;) {
    if (reads) {
      void* samples[8] = {NULL};
      dds_sample_info_t infos[8];
      const dds_return_t n = dds_take(reader, samples, infos, 8, 8);
      if (n > 0) {
        for (dds_return_t i = 0; i < n; ++i) taken += infos[i].valid_data ? 1 : 0;
        dds_return_loan(reader, samples, n);
        if (argc == 5) {
          FILE* t = fopen(argv[4], "w");
          if (t) {
            fprintf(t, "%llu\n", taken);
            fclose(t);
          }
        }
      }
    }
    dds_sleepfor(DDS_MSECS(20));
  }
}
