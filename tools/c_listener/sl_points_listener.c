/* sl_points_listener: subscribes to sensor_msgs::msg::dds_::PointCloud2_ and
 * prints one line per cloud received.
 *
 *   sl_points_listener [--topic rt/sl/points] [--domain N] [--count N]
 *                      [--timeout SECONDS]
 *
 * Exits 0 after --count clouds (default 1), 1 if --timeout seconds (default
 * 30, 0 = none) pass first, 2 on bad arguments or a DDS failure. Uses
 * CYCLONEDDS_URI like any Cyclone DDS program. Plain C11 on purpose: it uses
 * nothing but the idlc output of idl/ and libddsc. */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dds/dds.h"
#include "sensor_msgs/msg/PointCloud2.h"

typedef sensor_msgs_msg_dds__PointCloud2_ Cloud;

struct Options {
  const char* topic;
  dds_domainid_t domain;
  long count;
  double timeout_s;
};

static void usage(FILE* out) {
  fprintf(out,
          "usage: sl_points_listener [--topic NAME] [--domain N] [--count N] "
          "[--timeout SECONDS]\n"
          "  --topic    topic name (default rt/sl/points)\n"
          "  --domain   DDS domain id (default: Cyclone's default domain)\n"
          "  --count    exit 0 after this many clouds (default 1)\n"
          "  --timeout  exit 1 if the clouds have not arrived after this many\n"
          "             seconds (default 30, 0 = wait forever)\n");
}

static bool parseLong(const char* text, long min, long max, long* value) {
  char* end = NULL;
  errno = 0;
  const long v = strtol(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || v < min || v > max) return false;
  *value = v;
  return true;
}

/* Returns 0 if the arguments are fine, otherwise the exit code to use. */
static int parseOptions(int argc, char** argv, struct Options* opt) {
  opt->topic = "rt/sl/points";
  opt->domain = DDS_DOMAIN_DEFAULT;
  opt->count = 1;
  opt->timeout_s = 30.0;
  for (int i = 1; i < argc; ++i) {
    const char* arg = argv[i];
    if (strcmp(arg, "--help") == 0 || strcmp(arg, "-h") == 0) {
      usage(stdout);
      exit(0);
    }
    if (i + 1 >= argc) {
      fprintf(stderr, "sl_points_listener: %s: missing value or unknown option\n", arg);
      usage(stderr);
      return 2;
    }
    const char* value = argv[++i];
    long number = 0;
    if (strcmp(arg, "--topic") == 0) {
      opt->topic = value;
    } else if (strcmp(arg, "--domain") == 0) {
      if (!parseLong(value, 0, 232, &number)) {
        fprintf(stderr, "sl_points_listener: --domain %s: expected 0..232\n", value);
        return 2;
      }
      opt->domain = (dds_domainid_t)number;
    } else if (strcmp(arg, "--count") == 0) {
      if (!parseLong(value, 1, 1000000000L, &number)) {
        fprintf(stderr, "sl_points_listener: --count %s: expected a positive integer\n", value);
        return 2;
      }
      opt->count = number;
    } else if (strcmp(arg, "--timeout") == 0) {
      char* end = NULL;
      opt->timeout_s = strtod(value, &end);
      if (end == value || *end != '\0' || !(opt->timeout_s >= 0.0)) {
        fprintf(stderr, "sl_points_listener: --timeout %s: expected seconds >= 0\n", value);
        return 2;
      }
    } else {
      fprintf(stderr, "sl_points_listener: unknown option %s\n", arg);
      usage(stderr);
      return 2;
    }
  }
  return 0;
}

/* Field named `name` of datatype FLOAT32, or NULL. */
static const sensor_msgs_msg_dds__PointField_* findFloatField(const Cloud* cloud,
                                                              const char* name) {
  for (uint32_t i = 0; i < cloud->fields._length; ++i) {
    const sensor_msgs_msg_dds__PointField_* f = &cloud->fields._buffer[i];
    if (f->name != NULL && strcmp(f->name, name) == 0 &&
        f->datatype == sensor_msgs_msg_dds__PointField_Constants_FLOAT32) {
      return f;
    }
  }
  return NULL;
}

static bool hostIsBigEndian(void) {
  const uint16_t one = 1;
  uint8_t first;
  memcpy(&first, &one, 1);
  return first == 0;
}

/* Prints one line describing the cloud. */
static void printCloud(long index, const Cloud* cloud) {
  const size_t points = (size_t)cloud->width * cloud->height;
  const sensor_msgs_msg_dds__PointField_* z_field = findFloatField(cloud, "z");
  size_t finite = 0;
  double sum_z = 0.0;
  const bool swap = (cloud->is_bigendian != 0) != hostIsBigEndian();
  if (z_field != NULL && cloud->point_step >= z_field->offset + 4u &&
      cloud->row_step >= (size_t)cloud->width * cloud->point_step &&
      cloud->data._length >= (size_t)cloud->height * cloud->row_step) {
    for (uint32_t row = 0; row < cloud->height; ++row) {
      const uint8_t* p = cloud->data._buffer + (size_t)row * cloud->row_step + z_field->offset;
      for (uint32_t col = 0; col < cloud->width; ++col, p += cloud->point_step) {
        uint8_t bytes[4];
        memcpy(bytes, p, 4);
        if (swap) {
          uint8_t t = bytes[0];
          bytes[0] = bytes[3];
          bytes[3] = t;
          t = bytes[1];
          bytes[1] = bytes[2];
          bytes[2] = t;
        }
        float z;
        memcpy(&z, bytes, 4);
        if (isfinite(z)) {
          ++finite;
          sum_z += z;
        }
      }
    }
  }
  const char* frame_id = cloud->header.frame_id != NULL ? cloud->header.frame_id : "";
  printf("cloud %ld: %" PRIu32 " x %" PRIu32 " (width x height), point_step %" PRIu32
         ", %zu points, finite z %zu, mean z %.4f m, frame_id \"%s\", stamp %" PRId32 ".%09" PRIu32
         "%s\n",
         index, cloud->width, cloud->height, cloud->point_step, points, finite,
         finite > 0 ? sum_z / (double)finite : NAN, frame_id, cloud->header.stamp.sec,
         cloud->header.stamp.nanosec, z_field == NULL ? " (no float32 z field)" : "");
  fflush(stdout);
}

static int fail(const char* call, dds_return_t rc) {
  fprintf(stderr, "sl_points_listener: %s failed: %s\n", call, dds_strretcode(rc));
  return 2;
}

int main(int argc, char** argv) {
  struct Options opt;
  const int bad = parseOptions(argc, argv, &opt);
  if (bad != 0) return bad;

  const dds_entity_t participant = dds_create_participant(opt.domain, NULL, NULL);
  if (participant < 0) return fail("dds_create_participant", participant);
  int exit_code = 2;

  const dds_entity_t topic =
      dds_create_topic(participant, &sensor_msgs_msg_dds__PointCloud2__desc, opt.topic, NULL, NULL);
  if (topic < 0) {
    exit_code = fail("dds_create_topic", topic);
    goto done;
  }
  /* Reliable, keep-last 2: a slow listener sees the newest clouds instead of
   * slowing the publisher down. */
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 2);
  const dds_entity_t reader = dds_create_reader(participant, topic, qos, NULL);
  dds_delete_qos(qos);
  if (reader < 0) {
    exit_code = fail("dds_create_reader", reader);
    goto done;
  }
  const dds_entity_t has_data = dds_create_readcondition(reader, DDS_ANY_STATE);
  const dds_entity_t waitset = dds_create_waitset(participant);
  if (has_data < 0 || waitset < 0) {
    exit_code = fail("dds_create_readcondition/waitset", has_data < 0 ? has_data : waitset);
    goto done;
  }
  dds_return_t rc = dds_waitset_attach(waitset, has_data, 0);
  if (rc < 0) {
    exit_code = fail("dds_waitset_attach", rc);
    goto done;
  }

  const dds_time_t deadline =
      opt.timeout_s > 0.0 ? dds_time() + (dds_duration_t)(opt.timeout_s * 1e9) : DDS_NEVER;
  long received = 0;
  while (received < opt.count) {
    rc = dds_waitset_wait_until(waitset, NULL, 0, deadline);
    if (rc < 0) {
      exit_code = fail("dds_waitset_wait_until", rc);
      goto done;
    }
    if (rc == 0) {
      fprintf(stderr,
              "sl_points_listener: timeout: received %ld of %ld clouds on topic \"%s\" "
              "within %.1f s\n",
              received, opt.count, opt.topic, opt.timeout_s);
      exit_code = 1;
      goto done;
    }
    /* buf[0] == NULL: Cyclone lends the samples; no copy of the cloud data. */
    void* samples[4] = {NULL};
    dds_sample_info_t infos[4];
    const dds_return_t n = dds_take(reader, samples, infos, 4, 4);
    if (n < 0) {
      exit_code = fail("dds_take", n);
      goto done;
    }
    for (dds_return_t i = 0; i < n && received < opt.count; ++i) {
      if (infos[i].valid_data) printCloud(++received, (const Cloud*)samples[i]);
    }
    if (n > 0) dds_return_loan(reader, samples, n);
  }
  exit_code = 0;

done:
  dds_delete(participant); /* deletes all children */
  return exit_code;
}
