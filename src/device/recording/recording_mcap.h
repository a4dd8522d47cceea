// cdm's layout inside an MCAP file (docs/recording.md): which channels,
// schemas and encodings hold the raw reports and the poses, and where the
// device-info report goes. The container itself is io/mcap.h.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "cdm/cdm.h"
#include "device/protocol.h"
#include "device/recording/recording.h"
#include "device/recording/replay_format.h"

namespace cdm::recording {

// Topics, schema names and encodings, in one place for the writer, the
// reader and the docs.
constexpr const char *kReportTopic = "/cdm/report";
constexpr const char *kReportEncoding = "cdm.report.v1"; // the raw input report bytes, report ID first
constexpr const char *kPoseTopic = "/cdm/pose";
constexpr const char *kPoseSchema = "geometry_msgs/msg/PoseStamped"; // metres, quaternion x,y,z,w
constexpr const char *kStateTopic = "/cdm/state";
constexpr const char *kStateSchema = "cdm_msgs/msg/State"; // examples/ros2/cdm_msgs/msg/State.msg
constexpr const char *kRejectedTopic = "/cdm/rejected";
constexpr const char *kRejectedSchema = "cdm_msgs/msg/Rejected"; // examples/ros2/cdm_msgs/msg/Rejected.msg
// A state every 10 ms of device time (100 Hz), and at every report where
// buttons, flags or dropped change: the grip and velocity of a human hand
// move well below 50 Hz, and 1 kHz of them would take a third of the file
// (docs/recording.md, "Size"); the raw reports keep every sample.
constexpr uint64_t kStatePeriodUs = 10000;
constexpr const char *kDeviceMetadata = "cdm.device";
constexpr const char *kPoseFrame = "cdm";
// cdm.device metadata: CLOCK_REALTIME - CLOCK_MONOTONIC (ns, decimal) when
// the file was opened. Log time = host time (CLOCK_MONOTONIC) + this, so
// log times are wall-clock and never go back; a replay subtracts it again.
constexpr const char *kClockOffsetKey = "clock_offset_ns";

// A double with 17 significant digits (read back, it is the one written),
// '.' as the decimal point whatever the process's locale (std::to_chars).
void append_number(std::string &s, double v);

// The ros2msg definitions (ROS 2's .msg text with its dependencies, as
// rosbag2 stores them) of the pose and state channels.
extern const char *const kPoseDefinition;
extern const char *const kStateDefinition;
extern const char *const kRejectedDefinition;

// The CDR messages (little-endian, ROS 2's encoding) of one pose stamped
// `wall_ns` (ns since the epoch): geometry_msgs/PoseStamped in metres, and
// cdm_msgs/State with the rest of cdm_pose.
std::string pose_cdr(uint64_t wall_ns, const cdm_pose &p);
std::string state_cdr(uint64_t wall_ns, const cdm_pose &p);

// Creates an MCAP recording (recording.h's open_writer, format Mcap):
// `info` the device-info report, `di` what the protocol parser read in it,
// `compression` the chunks' ("zstd", "lz4", "none"; "" is zstd).
int open_mcap_writer(const std::string &path, const uint8_t *info, size_t info_len, const proto::DeviceInfoReport &di,
                     const std::string &compression, std::unique_ptr<Writer> &out, std::string &err);

// An MCAP recording as the replay transport reads it: the device-info report
// from the cdm.device metadata, the /cdm/report messages in file order
// (copied out of their chunks, compressed or not) with their host times
// (log time - clock_offset_ns; files without it: the log time). Pose and
// state channels, in any encoding, are not read. A file cut short keeps its
// complete chunks, with the warning. Errors: CDM_ERR_PARSE, "NAME: byte
// OFFSET: what".
int parse_mcap(std::vector<uint8_t> bytes, const std::string &name, replay::File &out, std::string &err);

} // namespace cdm::recording
