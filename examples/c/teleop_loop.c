/*
 * teleop_loop: the skeleton of a teleoperation client. Opens a master, runs a
 * 1 kHz loop on absolute deadlines (what a robot controller does), reads the
 * newest pose each cycle with cdm_get_pose (real-time safe: no lock, no
 * allocation), prints it at 10 Hz, and at the end reports how regular the loop
 * was and how old the poses were when it read them.
 *
 *   teleop_loop [URI] [--seconds S]      URI default "sim:"; S default: until Ctrl-C
 */
#define _POSIX_C_SOURCE 200809L

#include <cdm/cdm.h>

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define PERIOD_NS 1000000LL      /* 1 kHz */
#define PRINT_EVERY 100          /* cycles: 10 Hz */
#define LAT_BINS 100000          /* 1 us bins up to 100 ms; older poses go in the last bin */

static volatile sig_atomic_t stop_requested = 0;

static void on_signal(int sig) {
    (void)sig;
    stop_requested = 1;
}

static int64_t now_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (int64_t)t.tv_sec * 1000000000LL + t.tv_nsec;
}

static struct timespec to_timespec(int64_t ns) {
    struct timespec t = {(time_t)(ns / 1000000000LL), (long)(ns % 1000000000LL)};
    return t;
}

/* Latency percentiles from a 1 us histogram: exact to a microsecond, and the
 * loop never allocates. */
static double percentile_us(const uint32_t *hist, uint64_t n, double p) {
    uint64_t rank = (uint64_t)ceil(p / 100.0 * (double)n), seen = 0;
    if (rank == 0) rank = 1;
    for (int i = 0; i < LAT_BINS; i++) {
        seen += hist[i];
        if (seen >= rank) return i + 0.5;
    }
    return LAT_BINS;
}

static int usage(const char *argv0) {
    fprintf(stderr, "usage: %s [URI] [--seconds S]   (URI default \"sim:\"; runs until Ctrl-C without --seconds)\n",
            argv0);
    return 2;
}

int main(int argc, char **argv) {
    const char *uri = "sim:";
    double seconds = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--seconds") == 0 && i + 1 < argc) {
            char *end;
            seconds = strtod(argv[++i], &end);
            if (*end || !(seconds > 0)) {
                fprintf(stderr, "teleop_loop: --seconds wants a positive number, got \"%s\"\n", argv[i]);
                return 2;
            }
        } else if (argv[i][0] == '-' && argv[i][1] == '-') {
            return usage(argv[0]);
        } else {
            uri = argv[i];
        }
    }

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    cdm_device *dev = NULL;
    int rc = cdm_open(uri, &dev);
    if (rc != CDM_OK) {
        fprintf(stderr, "teleop_loop: cannot open \"%s\": %s: %s\n", uri, cdm_strerror(rc), cdm_thread_error());
        return 1;
    }
    cdm_pose pose = {.struct_size = sizeof pose};
    rc = cdm_wait_pose_after(dev, 0, 2000, &pose); /* the first pose, even one already published */
    if (rc != CDM_OK) {
        fprintf(stderr, "teleop_loop: no pose from \"%s\" within 2 s: %s: %s\n", uri, cdm_strerror(rc),
                cdm_thread_error());
        cdm_close(dev);
        return 1;
    }
    cdm_device_info info = {.struct_size = sizeof info};
    if (cdm_get_info(dev, &info) == CDM_OK)
        printf("opened %s (%s, serial %s, firmware %s, %.0f Hz reports)\n", info.uri, info.transport, info.serial,
               info.firmware, info.report_rate_hz);

    static uint32_t lat_hist[LAT_BINS];
    uint64_t cycles = 0, lat_n = 0, overruns = 0, stale = 0, errors = 0, fresh = 0;
    double p_mean = 0, p_m2 = 0, jitter_max = 0; /* Welford over the measured periods (ns) */
    uint32_t last_seq = pose.sequence, first_dropped = pose.dropped;
    const int64_t start = now_ns();
    const int64_t end = seconds > 0 ? start + (int64_t)(seconds * 1e9) : INT64_MAX;
    int64_t deadline = start, prev_wake = 0;

    while (!stop_requested) {
        deadline += PERIOD_NS;
        if (deadline >= end) break;
        struct timespec ts = to_timespec(deadline);
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR && !stop_requested) {
        }
        if (stop_requested) break;
        const int64_t wake = now_ns();

        rc = cdm_get_pose(dev, &pose);
        const int64_t read_at = now_ns();
        if (rc == CDM_OK || rc == CDM_ERR_STALE || rc == CDM_ERR_DISCONNECTED) {
            /* A robot would command here; this client only measures. */
            int64_t age_us = (read_at - (int64_t)pose.host_time_ns) / 1000;
            lat_hist[age_us < 0 ? 0 : age_us >= LAT_BINS ? LAT_BINS - 1 : age_us]++;
            lat_n++;
            if (pose.sequence != last_seq) fresh++;
            last_seq = pose.sequence;
            if (rc != CDM_OK) stale++;
        } else if (rc == CDM_ERR_END_OF_STREAM) {
            printf("end of stream\n");
            break;
        } else {
            errors++;
        }

        if (prev_wake) {
            double period = (double)(wake - prev_wake), d = period - p_mean;
            p_mean += d / (double)cycles;
            p_m2 += d * (period - p_mean);
            if (fabs(period - PERIOD_NS) > jitter_max) jitter_max = fabs(period - PERIOD_NS);
        }
        prev_wake = wake;
        cycles++;
        /* Late by more than a period: skip the missed cycles rather than run
         * them back to back (a controller must not burst). */
        if (wake - deadline > PERIOD_NS) {
            overruns++;
            deadline = wake - (wake - deadline) % PERIOD_NS;
        }
        if (cycles % PRINT_EVERY == 0)
            printf("t=%6.2fs #%-8u pos (%8.3f %8.3f %8.3f) mm  q (%+.3f %+.3f %+.3f %+.3f)  grip %.3f rad  "
                   "buttons %x flags %x\n",
                   (double)(wake - start) * 1e-9, pose.sequence, pose.position[0], pose.position[1],
                   pose.position[2], pose.orientation[0], pose.orientation[1], pose.orientation[2],
                   pose.orientation[3], pose.grip, pose.buttons, pose.flags);
    }

    cdm_stats st = {.struct_size = sizeof st};
    cdm_get_stats(dev, &st);
    cdm_close(dev);

    printf("\n%s after %.2f s, %llu cycles\n", stop_requested ? "stopped (signal)" : "done",
           (double)(now_ns() - start) * 1e-9, (unsigned long long)cycles);
    if (cycles < 2 || lat_n == 0) {
        fprintf(stderr, "teleop_loop: too few cycles for statistics\n");
        return 1;
    }
    double p_std = cycles > 2 ? sqrt(p_m2 / (double)(cycles - 2)) : 0;
    printf("loop period: mean %.1f us, std %.1f us, max jitter %.1f us, overruns %llu\n", p_mean / 1e3,
           p_std / 1e3, jitter_max / 1e3, (unsigned long long)overruns);
    printf("pose age at read (now - host_time_ns): p50 %.1f us, p90 %.1f us, p99 %.1f us, p99.9 %.1f us, "
           "max %.1f us\n",
           percentile_us(lat_hist, lat_n, 50), percentile_us(lat_hist, lat_n, 90), percentile_us(lat_hist, lat_n, 99),
           percentile_us(lat_hist, lat_n, 99.9), percentile_us(lat_hist, lat_n, 100));
    printf("poses: %llu new of %llu reads, %llu stale/disconnected, %llu errors; device: %llu reports, "
           "%u dropped in this run\n",
           (unsigned long long)fresh, (unsigned long long)lat_n, (unsigned long long)stale,
           (unsigned long long)errors, (unsigned long long)st.reports, pose.dropped - first_dropped);
    if (fresh == 0) {
        fprintf(stderr, "teleop_loop: the device sent no new pose during the run\n");
        return 1;
    }
    return errors ? 1 : 0;
}
