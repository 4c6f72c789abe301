// Writes requests the daemon cannot deserialize (test_malformed): `count`
// look-alike CommandRequests on rq/<ns>/commandRequest whose client_id is a
// string without its terminating NUL, then waits until the daemon's reader acknowledged
// them. Usage: malformed_writer NAMESPACE COUNT. Exit 0 on success.
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <dds/dds.h>

#include "CommandRequest.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: malformed_writer NAMESPACE COUNT\n");
    return 2;
  }
  char topic_name[512];
  snprintf(topic_name, sizeof topic_name, "rq/%s/commandRequest", argv[1]);
  const int count = atoi(argv[2]);
  const dds_entity_t participant = dds_create_participant(DDS_DOMAIN_DEFAULT, NULL, NULL);
  if (participant < 0) return 1;
  const dds_entity_t topic =
      dds_create_topic(participant, &sl_msgs_msg_dds__CommandRequest__desc, topic_name, NULL, NULL);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(10));
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
  dds_qset_data_representation(qos, 1, &xcdr1);
  const dds_entity_t writer = dds_create_writer(participant, topic, qos, NULL);
  dds_delete_qos(qos);
  if (topic < 0 || writer < 0) return 1;
  // Wait for the daemon's request reader.
  dds_publication_matched_status_t matched = {0};
  for (int i = 0; i < 200 && matched.current_count == 0; ++i) {
    dds_get_publication_matched_status(writer, &matched);
    if (matched.current_count == 0) dds_sleepfor(DDS_MSECS(50));
  }
  if (matched.current_count == 0) {
    fprintf(stderr, "malformed_writer: no request reader on %s\n", topic_name);
    return 1;
  }
  for (int i = 0; i < count; ++i) {
    sl_msgs_msg_dds__CommandRequest_ req;
    memset(&req, 0, sizeof req);
    static unsigned char unterminated[] = {'b', 'a', 'd'};  // a CDR string ends in NUL
    req.client_id._buffer = unterminated;
    req.client_id._length = req.client_id._maximum = sizeof unterminated;
    req.request_id = (uint64_t)(i + 1);
    req.command = 3;  // COMMAND_LIST_PATTERNS: harmless had it been read
    req.pattern = "";
    req.recording = "";
    if (dds_write(writer, &req) != DDS_RETCODE_OK) return 1;
  }
  if (dds_wait_for_acks(writer, DDS_SECS(10)) != DDS_RETCODE_OK) {
    fprintf(stderr, "malformed_writer: not acknowledged\n");
    return 1;
  }
  dds_delete(participant);
  return 0;
}
