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
constexpr const char *kPoseSchema = "foxglove.PoseInFrame"; // metres, quaternion x,y,z,w: Foxglove's 3D panel
constexpr const char *kStateTopic = "/cdm/state";
constexpr const char *kStateSchema = "cdm.State"; // the whole cdm_pose in the library's units
constexpr const char *kDeviceMetadata = "cdm.device";
constexpr const char *kPoseFrame = "cdm";

// A double with 17 significant digits (read back, it is the one written),
// '.' as the decimal point whatever the process's locale (std::to_chars).
void append_number(std::string &s, double v);

// The two JSON messages of one pose (exact: doubles with 17 significant
// digits, so a reader gets the library's numbers bit for bit).
std::string pose_json(uint64_t host_ns, const cdm_pose &p);
std::string state_json(uint64_t host_ns, const cdm_pose &p);

// Creates an MCAP recording (recording.h's open_writer, format Mcap):
// `info` the device-info report, `di` what the protocol parser read in it.
int open_mcap_writer(const std::string &path, const uint8_t *info, size_t info_len, const proto::DeviceInfoReport &di,
                     std::unique_ptr<Writer> &out, std::string &err);

// An MCAP recording as the replay transport reads it: the device-info report
// from the cdm.device metadata, the /cdm/report messages in file order as
// records pointing into the file's bytes (uncompressed chunks keep each
// message's bytes contiguous). A file cut short keeps its complete chunks,
// with the warning. Errors: CDM_ERR_PARSE, "NAME: byte OFFSET: what".
int parse_mcap(std::vector<uint8_t> bytes, const std::string &name, replay::File &out, std::string &err);

} // namespace cdm::recording
