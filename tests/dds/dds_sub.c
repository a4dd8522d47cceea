/*
 * A DDS subscriber in C for `cdm bridge --dds`, on Cyclone DDS's C API and
 * the types idlc generated from src/bridge/idl: what a C program without
 * ROS 2 would write. Two modes:
 *
 *   dds_sub check DOMAIN TOPIC_BASE FRAME_ID N TIMEOUT_S
 *       receives N poses (and joy, gripper, status) and checks the types the
 *       bridge's writers announce and the values: finite, metres within the
 *       device's reach, unit quaternion, stamps from the host clock, buttons
 *       0/1, statuses counting up. Exit 0 when all hold, 1 otherwise (each
 *       failure printed).
 *   dds_sub latency DOMAIN TOPIC_BASE N TIMEOUT_S
 *       the benchmark of docs/ros2.md: for N poses, the time from the
 *       report's receipt by libcdm (the pose's header stamp) to this
 *       program taking the sample, on the same host's clock; prints the
 *       median, p90, p99 and max.
 *
 * TOPIC_BASE is "rt/PREFIX/SERIAL/". Run with CYCLONEDDS_URI pointing at
 * the bridge's configuration (tests/dds/cyclonedds_lo.xml).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <dds/dds.h>

#include "cdm_msgs.h"
#include "geometry_msgs.h"
#include "sensor_msgs.h"
#include "std_msgs.h"

static int failures = 0;
#define CHECK(cond, ...)                                                                                               \
    do {                                                                                                               \
        if (!(cond)) {                                                                                                 \
            if (failures < 20) {                                                                                       \
                fprintf(stderr, "dds_sub: FAIL %s: ", #cond);                                                          \
                fprintf(stderr, __VA_ARGS__);                                                                          \
                fputc('\n', stderr);                                                                                   \
            }                                                                                                          \
            ++failures;                                                                                                \
        }                                                                                                              \
    } while (0)

static int64_t realtime_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int64_t stamp_ns(const builtin_interfaces_msg_dds__Time_ *t) {
    return (int64_t)t->sec * 1000000000 + t->nanosec;
}

static dds_entity_t make_reader(dds_entity_t pp, const dds_topic_descriptor_t *desc, const char *base,
                                const char *leaf, int reliable, int depth) {
    char name[512];
    snprintf(name, sizeof name, "%s%s", base, leaf);
    dds_qos_t *q = dds_create_qos();
    if (reliable)
        dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
    else
        dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_history(q, DDS_HISTORY_KEEP_LAST, depth);
    const dds_entity_t topic = dds_create_topic(pp, desc, name, NULL, NULL);
    if (topic < 0) {
        fprintf(stderr, "dds_sub: topic %s: %s\n", name, dds_strretcode(topic));
        exit(2);
    }
    const dds_entity_t r = dds_create_reader(pp, topic, q, NULL);
    dds_delete_qos(q);
    if (r < 0) {
        fprintf(stderr, "dds_sub: reader %s: %s\n", name, dds_strretcode(r));
        exit(2);
    }
    return r;
}

/* The type name every writer matched with `reader` announces must be `want`. */
static void check_matched_type(dds_entity_t reader, const char *want) {
    dds_instance_handle_t ih[8];
    const dds_return_t n = dds_get_matched_publications(reader, ih, 8);
    CHECK(n >= 1, "no writer matched for type %s", want);
    for (dds_return_t i = 0; i < n && i < 8; ++i) {
        dds_builtintopic_endpoint_t *ep = dds_get_matched_publication_data(reader, ih[i]);
        if (!ep) continue;
        CHECK(strcmp(ep->type_name, want) == 0, "writer of %s announces type %s, want %s", ep->topic_name,
              ep->type_name, want);
        dds_builtintopic_free_endpoint(ep);
    }
}

static int cmp_i64(const void *a, const void *b) {
    const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

static int run_latency(dds_entity_t pp, const char *base, int n, double timeout_s) {
    const dds_entity_t pose_r = make_reader(pp, &geometry_msgs_msg_dds__PoseStamped__desc, base, "pose", 0, 1);
    const dds_entity_t ws = dds_create_waitset(pp);
    const dds_entity_t rc_cond = dds_create_readcondition(pose_r, DDS_ANY_STATE);
    dds_waitset_attach(ws, rc_cond, 0);
    int64_t *lat = calloc((size_t)n, sizeof *lat);
    int got = 0;
    const int64_t end = realtime_ns() + (int64_t)(timeout_s * 1e9);
    while (got < n && realtime_ns() < end) {
        if (dds_waitset_wait(ws, NULL, 0, DDS_MSECS(100)) <= 0) continue;
        void *buf[1] = {NULL};
        dds_sample_info_t info[1];
        const dds_return_t k = dds_take(pose_r, buf, info, 1, 1);
        const int64_t now = realtime_ns();
        if (k == 1 && info[0].valid_data) {
            const geometry_msgs_msg_dds__PoseStamped_ *m = buf[0];
            lat[got++] = now - stamp_ns(&m->header.stamp);
        }
        if (k > 0) dds_return_loan(pose_r, buf, k);
    }
    if (got < n) {
        fprintf(stderr, "dds_sub: only %d of %d poses in %.0f s\n", got, n, timeout_s);
        free(lat);
        return 1;
    }
    qsort(lat, (size_t)n, sizeof *lat, cmp_i64);
    printf("report in (libcdm's receipt, header stamp) -> sample taken here, %d poses: median %.1f us, p90 %.1f us, "
           "p99 %.1f us, max %.1f us\n",
           n, (double)lat[n / 2] * 1e-3, (double)lat[(n * 9) / 10] * 1e-3, (double)lat[(n * 99) / 100] * 1e-3,
           (double)lat[n - 1] * 1e-3);
    free(lat);
    return 0;
}

static int run_check(dds_entity_t pp, const char *base, const char *frame_id, int n, double timeout_s) {
    const dds_entity_t pose_r = make_reader(pp, &geometry_msgs_msg_dds__PoseStamped__desc, base, "pose", 0, 1);
    const dds_entity_t joy_r = make_reader(pp, &sensor_msgs_msg_dds__Joy__desc, base, "joy", 0, 1);
    const dds_entity_t grip_r = make_reader(pp, &sensor_msgs_msg_dds__JointState__desc, base, "gripper", 0, 1);
    const dds_entity_t status_r = make_reader(pp, &cdm_msgs_msg_dds__Status__desc, base, "status", 1, 10);
    const int64_t t_start = realtime_ns();
    const int64_t end = t_start + (int64_t)(timeout_s * 1e9);
    int poses = 0, joys = 0, grips = 0, statuses = 0;
    uint64_t last_published = 0;
    int64_t last_stamp = 0;
    while ((poses < n || joys == 0 || grips == 0 || statuses == 0) && realtime_ns() < end) {
        void *buf[16] = {NULL};
        dds_sample_info_t info[16];
        dds_return_t k = dds_take(pose_r, buf, info, 16, 16);
        for (dds_return_t i = 0; i < k; ++i) {
            if (!info[i].valid_data) continue;
            const geometry_msgs_msg_dds__PoseStamped_ *m = buf[i];
            const int64_t now = realtime_ns(), st = stamp_ns(&m->header.stamp);
            const double *p = &m->pose.position.x;
            const geometry_msgs_msg_dds__Quaternion_ *q = &m->pose.orientation;
            /* The device's reach: cables of a 150 mm frame, the holder
             * within ~0.3 m of the frame's centre; metres, not mm. */
            CHECK(isfinite(p[0]) && isfinite(p[1]) && isfinite(p[2]) && fabs(p[0]) < 0.3 && fabs(p[1]) < 0.3 &&
                      fabs(p[2]) < 0.3,
                  "position %g %g %g m", p[0], p[1], p[2]);
            /* libcdm normalises the IMU quaternion in double precision. */
            const double norm = sqrt(q->x * q->x + q->y * q->y + q->z * q->z + q->w * q->w);
            CHECK(fabs(norm - 1.0) < 1e-9, "|q| = %.12f", norm);
            CHECK(strcmp(m->header.frame_id, frame_id) == 0, "frame_id \"%s\"", m->header.frame_id);
            /* Host clock: after we started (less the bridge's head start of
             * at most the timeout) and not in the future. */
            CHECK(st <= now && st > t_start - (int64_t)(timeout_s * 1e9), "stamp %lld vs now %lld", (long long)st,
                  (long long)now);
            CHECK(st >= last_stamp, "stamps go back: %lld after %lld", (long long)st, (long long)last_stamp);
            last_stamp = st;
            ++poses;
        }
        if (k > 0) dds_return_loan(pose_r, buf, k);
        k = dds_take(joy_r, buf, info, 16, 16);
        for (dds_return_t i = 0; i < k; ++i) {
            if (!info[i].valid_data) continue;
            const sensor_msgs_msg_dds__Joy_ *m = buf[i];
            CHECK(m->buttons._length == 3, "joy has %u buttons", (unsigned)m->buttons._length);
            for (uint32_t b = 0; b < m->buttons._length; ++b)
                CHECK(m->buttons._buffer[b] == 0 || m->buttons._buffer[b] == 1, "button %u = %d", (unsigned)b,
                      (int)m->buttons._buffer[b]);
            CHECK(m->axes._length == 0, "joy has %u axes", (unsigned)m->axes._length);
            CHECK(strcmp(m->header.frame_id, frame_id) == 0, "joy frame_id \"%s\"", m->header.frame_id);
            ++joys;
        }
        if (k > 0) dds_return_loan(joy_r, buf, k);
        k = dds_take(grip_r, buf, info, 16, 16);
        for (dds_return_t i = 0; i < k; ++i) {
            if (!info[i].valid_data) continue;
            const sensor_msgs_msg_dds__JointState_ *m = buf[i];
            CHECK(m->name._length == 1 && m->position._length == 1 && m->velocity._length == 0 &&
                      m->effort._length == 0,
                  "gripper joint state with %u names, %u positions", (unsigned)m->name._length,
                  (unsigned)m->position._length);
            if (m->name._length == 1 && m->position._length == 1) {
                const double g = m->position._buffer[0];
                CHECK(strcmp(m->name._buffer[0], "grip") == 0, "gripper joint \"%s\"", m->name._buffer[0]);
                /* the jaw: 0 (closed) .. 0.6 rad (open) in the simulation, plus Hall noise */
                CHECK(isfinite(g) && g > -0.05 && g < 0.7, "gripper %g rad", g);
            }
            CHECK(strcmp(m->header.frame_id, frame_id) == 0, "gripper frame_id \"%s\"", m->header.frame_id);
            ++grips;
        }
        if (k > 0) dds_return_loan(grip_r, buf, k);
        k = dds_take(status_r, buf, info, 16, 16);
        for (dds_return_t i = 0; i < k; ++i) {
            if (!info[i].valid_data) continue;
            const cdm_msgs_msg_dds__Status_ *m = buf[i];
            CHECK(m->published >= last_published, "published went back: %llu after %llu",
                  (unsigned long long)m->published, (unsigned long long)last_published);
            last_published = m->published;
            CHECK(!m->stale && !m->disconnected && !m->end_of_stream, "flags %u on a running sim", m->flags);
            CHECK(m->reports >= m->published, "reports %llu < published %llu", (unsigned long long)m->reports,
                  (unsigned long long)m->published);
            ++statuses;
        }
        if (k > 0) dds_return_loan(status_r, buf, k);
        dds_sleepfor(DDS_MSECS(2));
    }
    CHECK(poses >= n, "%d poses of %d in %.0f s", poses, n, timeout_s);
    CHECK(joys > 0 && grips > 0 && statuses > 0, "joy %d, gripper %d, status %d", joys, grips, statuses);
    check_matched_type(pose_r, "geometry_msgs::msg::dds_::PoseStamped_");
    check_matched_type(joy_r, "sensor_msgs::msg::dds_::Joy_");
    check_matched_type(grip_r, "sensor_msgs::msg::dds_::JointState_");
    check_matched_type(status_r, "cdm_msgs::msg::dds_::Status_");
    printf("dds_sub: %d poses, %d joy, %d gripper, %d status; %d failures\n", poses, joys, grips, statuses, failures);
    return failures ? 1 : 0;
}

static void usage(void) {
    fprintf(stderr, "usage: dds_sub check DOMAIN TOPIC_BASE FRAME_ID N TIMEOUT_S\n"
                    "       dds_sub latency DOMAIN TOPIC_BASE N TIMEOUT_S\n");
    exit(2);
}

int main(int argc, char **argv) {
    if (argc < 2) usage();
    const int check = strcmp(argv[1], "check") == 0;
    if (!(check && argc == 7) && !(strcmp(argv[1], "latency") == 0 && argc == 6)) usage();
    const long domain = strtol(argv[2], NULL, 10);
    const dds_entity_t pp = dds_create_participant((dds_domainid_t)domain, NULL, NULL);
    if (pp < 0) {
        fprintf(stderr, "dds_sub: participant: %s\n", dds_strretcode(pp));
        return 2;
    }
    const int n = atoi(argv[check ? 5 : 4]);
    const double timeout_s = atof(argv[check ? 6 : 5]);
    if (n <= 0 || !(timeout_s > 0)) usage();
    const int rc = check ? run_check(pp, argv[3], argv[4], n, timeout_s) : run_latency(pp, argv[3], n, timeout_s);
    dds_delete(pp);
    return rc;
}
