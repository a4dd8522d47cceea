// Cyclone DDS's C API, with the types idlc generated from idl/ at build
// time. Every sample is written as XCDR1 (plain CDR), the encoding ROS 2's
// rmw_cyclonedds reads and writes, whatever the writer side would default to.
#include "dds_publisher.h"

#include <time.h>

#include <cctype>
#include <cstring>
#include <utility>

#include <dds/dds.h>

#include "cdm_msgs.h"
#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "sensor_msgs.h"
#include "std_msgs.h"
#include "type_hash.h"

namespace cdm::bridge {

namespace {

std::string dds_error(const std::string &what, dds_return_t rc) {
    return what + ": " + dds_strretcode(rc);
}

// ROS time from a CLOCK_REALTIME nanosecond count. Never negative in
// practice; a clock before 1970 would give sec < 0, which ROS also allows.
builtin_interfaces_msg_dds__Time_ ros_time(int64_t ns) {
    builtin_interfaces_msg_dds__Time_ t{};
    int64_t sec = ns / 1000000000;
    int64_t rem = ns % 1000000000;
    if (rem < 0) {
        rem += 1000000000;
        --sec;
    }
    t.sec = int32_t(sec);
    t.nanosec = uint32_t(rem);
    return t;
}

// `ros_type`'s hash goes in USER_DATA, as rmw_cyclonedds does it.
dds_qos_t *make_qos(bool reliable, int depth, bool transient_local, const char *ros_type) {
    dds_qos_t *q = dds_create_qos();
    const std::string user_data = type_hash_user_data(ros_type);
    dds_qset_userdata(q, user_data.data(), user_data.size());
    if (reliable)
        dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
    else
        dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_history(q, DDS_HISTORY_KEEP_LAST, depth);
    dds_qset_durability(q, transient_local ? DDS_DURABILITY_TRANSIENT_LOCAL : DDS_DURABILITY_VOLATILE);
    const dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
    dds_qset_data_representation(q, 1, &xcdr1);
    return q;
}

} // namespace

std::string ros_name_token(const std::string &text) {
    if (text.empty()) return "unknown";
    std::string s;
    for (unsigned char c : text) s += (std::isalnum(c) || c == '_') ? char(c) : '_';
    if (std::isdigit(static_cast<unsigned char>(s[0]))) s = "sn_" + s;
    return s;
}

std::string check_prefix(const std::string &prefix) {
    if (prefix.empty()) return "is empty";
    size_t start = 0;
    for (;;) {
        const size_t slash = prefix.find('/', start);
        const std::string tok = prefix.substr(start, slash == std::string::npos ? std::string::npos : slash - start);
        if (tok.empty()) return "has an empty token (a leading, trailing or double '/')";
        if (std::isdigit(static_cast<unsigned char>(tok[0]))) return "token \"" + tok + "\" starts with a digit";
        for (unsigned char c : tok)
            if (!(std::isalnum(c) || c == '_'))
                return "token \"" + tok + "\" has '" + std::string(1, char(c)) +
                       "' (ROS 2 names allow letters, digits and '_')";
        if (slash == std::string::npos) return "";
        start = slash + 1;
    }
}

std::unique_ptr<DdsPublisher> DdsPublisher::create(const DdsConfig &c, std::string &err) {
    std::unique_ptr<DdsPublisher> p(new DdsPublisher());
    p->base_ = "rt/" + c.prefix + "/" + c.serial + "/";
    p->frame_id_ = c.frame_id;
    p->hardware_id_ = c.serial;
    p->participant_ = dds_create_participant(dds_domainid_t(c.domain), nullptr, nullptr);
    if (p->participant_ < 0) {
        err = dds_error("DDS participant on domain " + std::to_string(c.domain) +
                            " (check CYCLONEDDS_URI if it is set)",
                        p->participant_);
        p->participant_ = 0;
        return nullptr;
    }
    struct Spec {
        const dds_topic_descriptor_t *desc;
        const char *ros_type;
        const char *leaf; // under base_, or a ROS 2 topic of its own ("rt/...")
        bool reliable;
        int depth;
        bool transient_local;
        int32_t *writer;
    };
    // Teleop wants the newest pose, not a queue of old ones: best effort,
    // keep last 1 (what ROS 2 calls the sensor-data profile, but volatile
    // so that default ROS subscribers match too). The status must not be
    // lost and a late joiner should see the current state: reliable,
    // transient local, the last few kept so a short stale episode is seen.
    // /diagnostics: ROS 2's default QoS (reliable, volatile, keep last 10),
    // what diagnostic_updater publishes with and its readers expect.
    const Spec specs[] = {
        {&geometry_msgs_msg_dds__PoseStamped__desc, "geometry_msgs/msg/PoseStamped", "pose", false, 1, false,
         &p->pose_w_},
        {&sensor_msgs_msg_dds__Joy__desc, "sensor_msgs/msg/Joy", "joy", false, 1, false, &p->joy_w_},
        {&sensor_msgs_msg_dds__JointState__desc, "sensor_msgs/msg/JointState", "gripper", false, 1, false,
         &p->grip_w_},
        {&cdm_msgs_msg_dds__Status__desc, "cdm_msgs/msg/Status", "status", true, 10, true, &p->status_w_},
        {&diagnostic_msgs_msg_dds__DiagnosticArray__desc, "diagnostic_msgs/msg/DiagnosticArray", "rt/diagnostics",
         true, 10, false, &p->diag_w_},
    };
    for (const Spec &s : specs) {
        const std::string name = std::string(s.leaf).rfind("rt/", 0) == 0 ? s.leaf : p->base_ + s.leaf;
        dds_qos_t *q = make_qos(s.reliable, s.depth, s.transient_local, s.ros_type);
        const dds_entity_t topic = dds_create_topic(p->participant_, s.desc, name.c_str(), q, nullptr);
        dds_entity_t w = topic;
        if (topic >= 0) w = dds_create_writer(p->participant_, topic, q, nullptr);
        dds_delete_qos(q);
        if (w < 0) {
            err = dds_error(std::string(topic < 0 ? "DDS topic " : "DDS writer for ") + name, w);
            return nullptr; // the destructor deletes the participant and all it holds
        }
        *s.writer = w;
    }
    return p;
}

DdsPublisher::~DdsPublisher() {
    if (participant_ > 0) dds_delete(participant_);
}

bool DdsPublisher::publish_pose(const cdm_pose &p, int64_t stamp_ns, std::string &err) {
    std_msgs_msg_dds__Header_ h{};
    h.stamp = ros_time(stamp_ns);
    // idlc's C types hold non-const char*; Cyclone only reads it on write.
    h.frame_id = const_cast<char *>(frame_id_.c_str());

    geometry_msgs_msg_dds__PoseStamped_ ps{};
    ps.header = h;
    ps.pose.position.x = p.position[0] * 1e-3; // mm -> m
    ps.pose.position.y = p.position[1] * 1e-3;
    ps.pose.position.z = p.position[2] * 1e-3;
    ps.pose.orientation.w = p.orientation[0]; // cdm: w,x,y,z; ROS: x,y,z,w
    ps.pose.orientation.x = p.orientation[1];
    ps.pose.orientation.y = p.orientation[2];
    ps.pose.orientation.z = p.orientation[3];
    dds_return_t rc = dds_write(pose_w_, &ps);
    if (rc != DDS_RETCODE_OK) {
        err = dds_error("DDS write " + base_ + "pose", rc);
        return false;
    }

    int32_t buttons[3] = {(p.buttons & CDM_BUTTON_CLUTCH) ? 1 : 0, (p.buttons & CDM_BUTTON_AUX) ? 1 : 0,
                          (p.buttons & CDM_BUTTON_MARK) ? 1 : 0};
    sensor_msgs_msg_dds__Joy_ joy{};
    joy.header = h;
    joy.buttons._maximum = joy.buttons._length = 3;
    joy.buttons._buffer = buttons;
    joy.buttons._release = false;
    if ((rc = dds_write(joy_w_, &joy)) != DDS_RETCODE_OK) {
        err = dds_error("DDS write " + base_ + "joy", rc);
        return false;
    }

    // The gripper as a one-joint JointState: its opening in radians.
    char joint_name[] = "grip";
    char *names[1] = {joint_name};
    double position[1] = {p.grip};
    sensor_msgs_msg_dds__JointState_ g{};
    g.header = h;
    g.name._maximum = g.name._length = 1;
    g.name._buffer = names;
    g.name._release = false;
    g.position._maximum = g.position._length = 1;
    g.position._buffer = position;
    g.position._release = false;
    if ((rc = dds_write(grip_w_, &g)) != DDS_RETCODE_OK) {
        err = dds_error("DDS write " + base_ + "gripper", rc);
        return false;
    }
    return true;
}

bool DdsPublisher::publish_status(uint32_t flags, int64_t pose_stamp_ns, uint32_t sequence, uint64_t device_time_us,
                                  const StatusCounts &n, std::string &err) {
    cdm_msgs_msg_dds__Status_ s{};
    s.header.stamp = ros_time(pose_stamp_ns);
    s.header.frame_id = const_cast<char *>(frame_id_.c_str());
    s.stale = (flags & CDM_POSE_STALE) != 0;
    s.disconnected = (flags & CDM_POSE_DISCONNECTED) != 0;
    s.compensated = (flags & CDM_POSE_COMPENSATED) != 0;
    s.out_of_workspace = (flags & CDM_POSE_OUT_OF_WORKSPACE) != 0;
    s.end_of_stream = (flags & CDM_POSE_END_OF_STREAM) != 0;
    s.flags = flags;
    s.report_sequence = sequence;
    s.device_time_us = device_time_us;
    s.reports = n.reports;
    s.dropped = n.dropped;
    s.malformed = n.malformed;
    s.published = n.published;
    s.skipped = n.skipped;
    const dds_return_t rc = dds_write(status_w_, &s);
    if (rc != DDS_RETCODE_OK) {
        err = dds_error("DDS write " + base_ + "status", rc);
        return false;
    }
    return publish_diagnostics(flags, n, err);
}

bool DdsPublisher::publish_diagnostics(uint32_t flags, const StatusCounts &n, std::string &err) {
    // The worst condition names the level and the message.
    uint8_t level = 0; // OK
    std::string message = "ok";
    if (flags & CDM_POSE_END_OF_STREAM) level = 3, message = "end of stream: the replay or script ended";
    else if (flags & CDM_POSE_DISCONNECTED) level = 2, message = "disconnected: the pose is the last good one";
    else if (flags & CDM_POSE_STALE) level = 1, message = "stale: no report for longer than the stale timeout";
    else if (flags & CDM_POSE_OUT_OF_WORKSPACE) level = 1, message = "out of workspace: the position is held";
    const std::pair<const char *, std::string> kv[] = {
        {"flags", std::to_string(flags)},           {"reports", std::to_string(n.reports)},
        {"dropped", std::to_string(n.dropped)},     {"malformed", std::to_string(n.malformed)},
        {"published", std::to_string(n.published)}, {"skipped", std::to_string(n.skipped)},
        {"compensated", (flags & CDM_POSE_COMPENSATED) ? "true" : "false"},
    };
    diagnostic_msgs_msg_dds__KeyValue_ values[sizeof kv / sizeof kv[0]];
    for (size_t i = 0; i < sizeof kv / sizeof kv[0]; ++i) {
        values[i].key = const_cast<char *>(kv[i].first);
        values[i].value = const_cast<char *>(kv[i].second.c_str());
    }
    const std::string name = "cdm bridge: " + hardware_id_;
    diagnostic_msgs_msg_dds__DiagnosticStatus_ st{};
    st.level = level;
    st.name = const_cast<char *>(name.c_str());
    st.message = const_cast<char *>(message.c_str());
    st.hardware_id = const_cast<char *>(hardware_id_.c_str());
    st.values._maximum = st.values._length = uint32_t(sizeof kv / sizeof kv[0]);
    st.values._buffer = values;
    st.values._release = false;
    diagnostic_msgs_msg_dds__DiagnosticArray_ a{};
    // Diagnostics are stamped when they are published (ROS time).
    timespec now{};
    clock_gettime(CLOCK_REALTIME, &now);
    a.header.stamp = ros_time(int64_t(now.tv_sec) * 1000000000 + now.tv_nsec);
    a.header.frame_id = const_cast<char *>("");
    a.status._maximum = a.status._length = 1;
    a.status._buffer = &st;
    a.status._release = false;
    const dds_return_t rc = dds_write(diag_w_, &a);
    if (rc != DDS_RETCODE_OK) {
        err = dds_error("DDS write rt/diagnostics", rc);
        return false;
    }
    return true;
}

} // namespace cdm::bridge
