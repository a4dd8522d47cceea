// The DDS side of `cdm bridge --dds`: one Cyclone DDS participant with the
// writers of the ROS 2 topics (docs/ros2.md). It knows the public cdm_pose
// and nothing else of libcdm; src/cli/bridge_cmd.cpp drives it.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include <cdm/cdm.h>

namespace cdm::bridge {

struct DdsConfig {
    uint32_t domain = 0;
    std::string prefix = "cdm";     // topic names: rt/<prefix>/<serial>/<leaf>
    std::string serial;             // a valid ROS 2 name token (ros_name_token)
    std::string frame_id = "cdm";
};

// What the status topic says beyond the pose's own fields.
struct StatusCounts {
    uint64_t reports = 0, dropped = 0, malformed = 0, published = 0, skipped = 0;
};

class DdsPublisher {
public:
    // Creates the participant, topics and writers; nullptr and `err` set
    // (Cyclone's own words) when DDS cannot start, e.g. a bad CYCLONEDDS_URI.
    static std::unique_ptr<DdsPublisher> create(const DdsConfig &c, std::string &err);
    ~DdsPublisher();
    DdsPublisher(const DdsPublisher &) = delete;
    DdsPublisher &operator=(const DdsPublisher &) = delete;

    // Writes pose, joy and gripper (sensor_msgs/JointState) for one pose, stamped stamp_ns (ROS time:
    // CLOCK_REALTIME, ns). False and `err` on a DDS failure.
    bool publish_pose(const cdm_pose &p, int64_t stamp_ns, std::string &err);
    // Writes a status: the newest published pose's stamp, sequence and
    // device time (zeros before the first), `flags` now, and the counts;
    // and the same health on /diagnostics (publish_diagnostics).
    bool publish_status(uint32_t flags, int64_t pose_stamp_ns, uint32_t sequence, uint64_t device_time_us,
                        const StatusCounts &n, std::string &err);

    // One diagnostic_msgs/DiagnosticArray on /diagnostics (DDS rt/diagnostics)
    // with one status named "cdm bridge: SERIAL", hardware_id the serial:
    // level OK, WARN (stale, out of workspace), ERROR (disconnected) or
    // STALE (end of stream), the condition in words, the counts as values.
    bool publish_diagnostics(uint32_t flags, const StatusCounts &n, std::string &err);

    // "rt/<prefix>/<serial>/" : the DDS names' common start.
    const std::string &topic_base() const { return base_; }

private:
    DdsPublisher() = default;
    std::string base_, frame_id_, hardware_id_;
    int32_t participant_ = 0, pose_w_ = 0, joy_w_ = 0, grip_w_ = 0, status_w_ = 0, diag_w_ = 0;
};

// A ROS 2 name token for `text` (a device serial): characters other than
// [A-Za-z0-9_] become '_', and a leading digit gets an "sn_" in front (ROS 2
// topic name tokens may not start with one). Empty text gives "unknown".
std::string ros_name_token(const std::string &text);

// Empty if `prefix` is a valid ROS 2 topic prefix (tokens of [A-Za-z0-9_]
// separated by single '/', none starting with a digit, no leading or
// trailing '/'); otherwise what is wrong with it.
std::string check_prefix(const std::string &prefix);

} // namespace cdm::bridge
