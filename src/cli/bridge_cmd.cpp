// `cdm bridge URI --dds`: the master on the network as ROS 2 topics, through
// the public C API (cdm_wait_pose_after, cdm_get_pose, cdm_get_stats) and
// the DDS writers of src/bridge (docs/ros2.md).
#include <time.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <thread>

#include <cdm/cdm.h>
#include "commands.h"
#ifdef CDM_HAVE_DDS
#include "bridge/dds_publisher.h"
#endif

namespace cdm::cli {

namespace {

struct BridgeArgs {
    std::string uri, calib, prefix = "cdm", frame_id = "cdm";
    bool dds = false;
    unsigned domain = 0;
    bool domain_given = false; // --domain on the command line: ROS_DOMAIN_ID is not read
    double seconds = 0, rate = 0, status_rate = 10;
};

#ifdef CDM_HAVE_DDS
volatile std::sig_atomic_t g_stop = 0;
void on_stop_signal(int) { g_stop = 1; }

// ROS time is the system clock; libcdm stamps receipt with CLOCK_MONOTONIC.
// The offset between them is read at every conversion (two vDSO reads), so
// a clock step (NTP) shows up in the next stamp, not never.
int64_t monotonic_to_realtime_ns(uint64_t mono_ns) {
    timespec rt{}, mo{};
    clock_gettime(CLOCK_REALTIME, &rt);
    clock_gettime(CLOCK_MONOTONIC, &mo);
    const int64_t rt_ns = int64_t(rt.tv_sec) * 1000000000 + rt.tv_nsec;
    const int64_t mo_ns = int64_t(mo.tv_sec) * 1000000000 + mo.tv_nsec;
    return int64_t(mono_ns) + (rt_ns - mo_ns);
}

// The domain as ROS 2 chooses it: --domain, else ROS_DOMAIN_ID (unset or
// empty: 0), which must then be a domain id ROS 2 accepts (0..232).
unsigned domain_id(const BridgeArgs &a) {
    if (a.domain_given) return a.domain;
    const char *env = std::getenv("ROS_DOMAIN_ID");
    if (!env || !*env) return 0;
    unsigned v = 0;
    const char *end = env + std::strlen(env);
    const auto r = std::from_chars(env, end, v);
    if (r.ec != std::errc() || r.ptr != end || v > 232)
        throw UsageError(std::string("ROS_DOMAIN_ID=\"") + env +
                         "\" is not a ROS 2 domain id (an integer 0..232); set it right or pass --domain");
    return v;
}

int open_device(const BridgeArgs &a, cdm_device *&dev) {
    int rc = cdm_open(a.uri.c_str(), &dev);
    if (rc != CDM_OK) return report_error("open " + a.uri, rc);
    if (!a.calib.empty()) {
        cdm_calibration *cal = nullptr;
        if ((rc = cdm_calibration_load(a.calib.c_str(), &cal)) != CDM_OK) {
            cdm_close(dev);
            dev = nullptr;
            return report_error("--calibration " + a.calib, rc);
        }
        rc = cdm_set_calibration(dev, cal); // the device keeps its own reference
        cdm_calibration_free(cal);
        if (rc != CDM_OK) {
            cdm_close(dev);
            dev = nullptr;
            return report_error("--calibration " + a.calib, rc);
        }
    }
    return kExitOk;
}

struct DeviceCloser {
    void operator()(cdm_device *d) const { cdm_close(d); }
};

// The DDS participant and writers for the device `info` describes, and the
// line that says what is bridged where; null (the message on stderr) when
// Cyclone DDS refuses them.
std::unique_ptr<bridge::DdsPublisher> start_publisher(const BridgeArgs &a, const cdm_device_info &info) {
    bridge::DdsConfig cfg;
    cfg.domain = domain_id(a);
    cfg.prefix = a.prefix;
    cfg.serial = bridge::ros_name_token(info.serial);
    cfg.frame_id = a.frame_id;
    if (cfg.serial != info.serial)
        std::fprintf(stderr, "cdm: serial \"%s\" is not a ROS 2 name token; the topics use \"%s\"\n", info.serial,
                     cfg.serial.c_str());
    std::string err;
    auto pub = bridge::DdsPublisher::create(cfg, err);
    if (!pub) {
        std::fprintf(stderr, "cdm: %s\n", err.c_str());
        return nullptr;
    }
    const std::string &base = pub->topic_base();
    std::printf("bridging %s (serial %s) to DDS domain %u: %spose (geometry_msgs/msg/PoseStamped), %sjoy "
                "(sensor_msgs/msg/Joy), %sgripper (sensor_msgs/msg/JointState), %sstatus (cdm_msgs/msg/Status), "
                "rt/diagnostics (diagnostic_msgs/msg/DiagnosticArray); Ctrl-C stops\n",
                info.uri, info.serial, cfg.domain, base.c_str(), base.c_str(), base.c_str(), base.c_str());
    std::fflush(stdout);
    return pub;
}

int cmd_bridge_dds(const BridgeArgs &a) {
    if (std::string why = bridge::check_prefix(a.prefix); !why.empty())
        throw UsageError("--prefix \"" + a.prefix + "\" " + why);
    domain_id(a); // a bad ROS_DOMAIN_ID is a usage error before the device opens
    cdm_device *raw_dev = nullptr;
    if (int rc = open_device(a, raw_dev); rc != kExitOk) return rc;
    std::unique_ptr<cdm_device, DeviceCloser> dev(raw_dev);
    cdm_device_info info{};
    info.struct_size = sizeof info;
    if (int rc = cdm_get_info(dev.get(), &info); rc != CDM_OK) return report_error("get info", rc);

    auto pub = start_publisher(a, info);
    if (!pub) return kExitFailure;
    std::string err;

    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
    const uint64_t t0 = now_ns();
    const uint64_t end = a.seconds > 0 ? t0 + uint64_t(a.seconds * 1e9) : UINT64_MAX;
    const uint64_t pose_period = a.rate > 0 ? uint64_t(1e9 / a.rate) : 0;
    const uint64_t status_period = a.status_rate > 0 ? uint64_t(1e9 / a.status_rate) : 0;
    uint64_t next_pose = 0, next_status = t0, last_hs = 0, statuses = 0;
    uint32_t last_flags = UINT32_MAX; // forces the first status
    int64_t last_stamp = 0;
    uint32_t last_seq = 0;
    uint64_t last_dev_us = 0;
    bridge::StatusCounts counts;
    bool ended = false;
    // The wait is cut short so that a stall is noticed (the stale flag) and
    // the status period kept even when no report comes.
    constexpr uint64_t kMaxWaitNs = 20000000;

    while (!g_stop && now_ns() < end) {
        uint64_t now = now_ns();
        if (pose_period && now < next_pose) { // --rate: nothing to publish before next_pose
            const uint64_t until = std::min({next_pose, status_period ? next_status : next_pose, end});
            if (until > now) std::this_thread::sleep_for(std::chrono::nanoseconds(until - now));
        }
        now = now_ns();
        uint64_t deadline = std::min(now + kMaxWaitNs, end);
        if (status_period) deadline = std::min(deadline, std::max(next_status, now));
        cdm_pose p{};
        p.struct_size = sizeof p;
        // Rounded up: a 0 ms wait only looks, and would spin until the deadline.
        int rc = cdm_wait_pose_after(dev.get(), last_hs, int((deadline - now + 999999) / 1000000), &p);
        if (rc == CDM_ERR_TIMEOUT) rc = cdm_get_pose(dev.get(), &p); // the flags now (stale), not at the last report
        now = now_ns();
        const bool have_pose = rc != CDM_ERR_NO_DATA && !(p.flags & CDM_POSE_NO_POSITION);
        if (have_pose && p.host_sequence > last_hs && (!pose_period || now >= next_pose)) {
            const int64_t stamp = monotonic_to_realtime_ns(p.host_time_ns);
            if (!pub->publish_pose(p, stamp, err)) {
                std::fprintf(stderr, "cdm: %s\n", err.c_str());
                return kExitFailure;
            }
            counts.skipped += p.host_sequence - last_hs - 1;
            ++counts.published;
            last_hs = p.host_sequence;
            last_stamp = stamp;
            last_seq = p.sequence;
            last_dev_us = p.device_time_us;
            if (pose_period) next_pose = std::max(next_pose + pose_period, now);
        }
        if (rc == CDM_ERR_END_OF_STREAM) ended = true;
        const uint32_t flags = p.flags & ~uint32_t(CDM_POSE_NO_POSITION);
        if (flags != last_flags || (status_period && now >= next_status) || ended) {
            cdm_stats st{};
            st.struct_size = sizeof st;
            cdm_get_stats(dev.get(), &st);
            counts.reports = st.reports;
            counts.dropped = st.dropped;
            counts.malformed = st.malformed;
            if (!pub->publish_status(flags, last_stamp, last_seq, last_dev_us, counts, err)) {
                std::fprintf(stderr, "cdm: %s\n", err.c_str());
                return kExitFailure;
            }
            ++statuses;
            last_flags = flags;
            if (status_period) next_status = std::max(next_status + status_period, now);
        }
        if (ended) break;
    }
    std::printf("published %llu poses (%llu reports not published: --rate or load) and %llu statuses in %.2f s%s\n",
                (unsigned long long)counts.published, (unsigned long long)counts.skipped,
                (unsigned long long)statuses, double(now_ns() - t0) * 1e-9, ended ? " (end of stream)" : "");
    return kExitOk;
}
#endif

int cmd_bridge(const BridgeArgs &a) {
    if (!a.dds) throw UsageError("bridge: say which network to bridge to: --dds (the only one so far)");
#ifdef CDM_HAVE_DDS
    return cmd_bridge_dds(a);
#else
    std::fprintf(stderr, "cdm: bridge --dds: this cdm was built without Cyclone DDS (apt install cyclonedds-dev "
                         "cyclonedds-tools, then configure again)\n");
    return kExitFailure;
#endif
}

} // namespace

void add_bridge_command(CLI::App &app) {
    auto *b = app.add_subcommand("bridge", "Publish the master on the network: --dds, as ROS 2 topics (docs/ros2.md)");
    static BridgeArgs a;
    b->add_option("URI", a.uri, "device URI: sim:[?options], replay:FILE, hid:/dev/hidrawN, serial:SN")->required();
    b->add_flag("--dds", a.dds,
                "publish over DDS (Cyclone DDS) with ROS 2's names and types: rt/PREFIX/SERIAL/{pose,joy,gripper,status}");
    static CLI::Option *domain_opt =
        b->add_option("--domain", a.domain, "DDS domain id (default: $ROS_DOMAIN_ID, else 0)")
            ->check(range(0, 232))
            ->default_str(""); // not a fixed 0: the environment's when not given
    b->add_option("--prefix", a.prefix, "topic prefix (ROS 2 name tokens separated by '/')");
    b->add_option("--frame-id", a.frame_id, "header.frame_id of pose and joy");
    b->add_option("--rate", a.rate, "publish at most this many poses per second (0: every report)")
        ->check(range(0, 100000));
    b->add_option("--status-rate", a.status_rate,
                  "status messages per second besides those on every flag change (0: on changes only)")
        ->check(range(0, 1000));
    b->add_option("--calibration", a.calib, "apply this calibration (CALIB.json from `cdm calib fit`)");
    b->add_option("--seconds", a.seconds, "stop after this many seconds (0: until Ctrl-C, SIGTERM or the end)")
        ->check(range(0, 1e9));
    static std::vector<std::string> plugins;
    add_plugin_option(b, plugins);
    b->callback([] {
        select_command([] {
            if (int rc = load_plugins(plugins); rc != kExitOk) return rc;
            a.domain_given = domain_opt->count() > 0;
            return cmd_bridge(a);
        });
    });
}

} // namespace cdm::cli
