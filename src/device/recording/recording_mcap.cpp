#include "device/recording/recording_mcap.h"

#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>

#include "device/protocol.h"
#include "io/mcap.h"

namespace cdm::recording {

namespace {

// JSON Schemas (draft 2020-12 vocabulary, what Foxglove reads). The pose
// follows Foxglove's published foxglove.PoseInFrame, so its 3D panel draws
// it as is; cdm.State carries the rest of cdm_pose for plots.
const char *const kPoseSchemaJson = R"json({
  "title": "foxglove.PoseInFrame",
  "description": "The master's holder pose in metres, quaternion x,y,z,w (device frame)",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "title": "time", "properties": {
      "sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
    "frame_id": {"type": "string"},
    "pose": {"type": "object", "title": "foxglove.Pose", "properties": {
      "position": {"type": "object", "title": "foxglove.Vector3", "properties": {
        "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
      "orientation": {"type": "object", "title": "foxglove.Quaternion", "properties": {
        "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}}}}
  }
})json";

const char *const kStateSchemaJson = R"json({
  "title": "cdm.State",
  "description": "cdm_pose as libcdm published it (include/cdm/cdm.h): mm, mm/s, rad, device frame",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "properties": {
      "sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
    "sequence": {"type": "integer", "description": "device report counter"},
    "device_time_us": {"type": "integer", "description": "device clock at sampling"},
    "position_mm": {"type": "object", "properties": {
      "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
    "orientation": {"type": "object", "description": "unit quaternion", "properties": {
      "w": {"type": "number"}, "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
    "grip_rad": {"type": "number", "description": "jaw opening, 0 = closed"},
    "buttons": {"type": "integer", "description": "cdm_button bits: 1 clutch, 2 aux, 4 mark"},
    "flags": {"type": "integer", "description": "cdm_pose_flag bits"},
    "velocity_mm_s": {"type": "object", "properties": {
      "x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
    "dropped": {"type": "integer", "description": "reports lost so far"}
  }
})json";

// JSON has no NaN; libcdm publishes none, but a null says so if it ever did.
void num(std::string &s, double v) {
    if (!std::isfinite(v)) {
        s += "null";
        return;
    }
    append_number(s, v);
}
void stamp(std::string &s, uint64_t ns) {
    s += "{\"sec\":" + std::to_string(ns / 1000000000u) + ",\"nsec\":" + std::to_string(ns % 1000000000u) + "}";
}
void xyz(std::string &s, const double *v, double scale) {
    s += "{\"x\":";
    num(s, v[0] * scale);
    s += ",\"y\":";
    num(s, v[1] * scale);
    s += ",\"z\":";
    num(s, v[2] * scale);
    s += "}";
}
// A cdm quaternion (w, x, y, z) as a JSON object with its keys in `order`
// ("xyzw" for Foxglove and ROS, "wxyz" for cdm's own state channel).
void quat(std::string &s, const double q[4], const char *order) {
    s += "{";
    for (const char *k = order; *k; ++k) {
        if (k != order) s += ",";
        s += std::string("\"") + *k + "\":";
        num(s, q[*k == 'w' ? 0 : *k - 'x' + 1]);
    }
    s += "}";
}

std::string hex(const uint8_t *p, size_t n) {
    static const char d[] = "0123456789abcdef";
    std::string s;
    for (size_t i = 0; i < n; ++i) {
        s.push_back(d[p[i] >> 4]);
        s.push_back(d[p[i] & 15]);
    }
    return s;
}
int nibble(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

class McapWriter final : public Writer {
public:
    int open(const std::string &path, const uint8_t *info, size_t info_len, const proto::DeviceInfoReport &di,
             std::string &err) {
        const std::string version = std::to_string(CDM_VERSION_MAJOR) + "." + std::to_string(CDM_VERSION_MINOR) +
                                    "." + std::to_string(CDM_VERSION_PATCH);
        // No well-known profile fits (ros1/ros2 need their message
        // encodings): the profile names cdm's own layout.
        if (!w_.open(path, "cdm", "libcdm " + version, err)) return CDM_ERR_IO;
        const uint16_t report_schema = w_.add_schema(kReportEncoding, "", "");
        report_ = w_.add_channel(report_schema, kReportTopic, kReportEncoding,
                                 {{"layout", "docs/protocol.md, input report 0x01, report ID first"},
                                  {"protocol_version", std::to_string(di.protocol_version)}});
        pose_ = w_.add_channel(w_.add_schema(kPoseSchema, "jsonschema", kPoseSchemaJson), kPoseTopic, "json");
        state_ = w_.add_channel(w_.add_schema(kStateSchema, "jsonschema", kStateSchemaJson), kStateTopic, "json");
        char rate[32];
        std::snprintf(rate, sizeof rate, "%g", double(di.report_rate_hz));
        const io_entries entries = {
            {"info_report_hex", hex(info, info_len)},
            {"serial", di.serial},
            {"firmware", std::to_string(di.fw_major) + "." + std::to_string(di.fw_minor) + "." +
                             std::to_string(di.fw_patch)},
            {"protocol_version", std::to_string(di.protocol_version)},
            {"report_rate_hz", rate},
            {"time", "log_time = host receipt time, ns, CLOCK_MONOTONIC of the recording machine"},
            {"library", "libcdm " + version},
        };
        return w_.add_metadata(kDeviceMetadata, entries, err) ? CDM_OK : CDM_ERR_IO;
    }

    int write(uint64_t host_ns, const uint8_t *report, size_t len, const cdm_pose *pose, std::string &err) override {
        if (!report || len == 0 || len > replay::kMaxReport) {
            err = "report of " + std::to_string(len) + " bytes (1..1024)";
            return CDM_ERR_INVALID_ARG;
        }
        // parse_mcap refuses a report channel whose log time goes back.
        if (!replay::host_time_in_order(host_ns, last_ns_, reports_, err)) return CDM_ERR_INVALID_ARG;
        if (!w_.write_message(report_, host_ns, report, len, err)) return CDM_ERR_IO;
        ++reports_;
        last_ns_ = host_ns;
        if (!pose) return CDM_OK;
        const std::string p = pose_json(host_ns, *pose), s = state_json(host_ns, *pose);
        if (!w_.write_message(pose_, host_ns, reinterpret_cast<const uint8_t *>(p.data()), p.size(), err) ||
            !w_.write_message(state_, host_ns, reinterpret_cast<const uint8_t *>(s.data()), s.size(), err))
            return CDM_ERR_IO;
        return CDM_OK;
    }

    int close(std::string &err) override { return w_.close(err) ? CDM_OK : CDM_ERR_IO; }
    uint64_t reports() const override { return reports_; }

private:
    using io_entries = mcap::StringMap;
    mcap::Writer w_;
    uint16_t report_ = 0, pose_ = 0, state_ = 0;
    uint64_t reports_ = 0;
    uint64_t last_ns_ = 0; // the last report's log time
};

int parse_error(const std::string &name, size_t offset, const std::string &what, std::string &err) {
    err = name + ": byte " + std::to_string(offset) + ": " + what;
    return CDM_ERR_PARSE;
}

} // namespace

void append_number(std::string &s, double v) {
    char b[32];
    const auto r = std::to_chars(b, b + sizeof b, v, std::chars_format::general, 17);
    s.append(b, r.ptr);
}

std::string pose_json(uint64_t host_ns, const cdm_pose &p) {
    std::string s = "{\"timestamp\":";
    stamp(s, host_ns);
    s += ",\"frame_id\":\"";
    s += kPoseFrame;
    s += "\",\"pose\":{\"position\":";
    xyz(s, p.position, 1e-3);
    // cdm_pose is w,x,y,z; Foxglove (and ROS) x,y,z,w.
    s += ",\"orientation\":";
    quat(s, p.orientation, "xyzw");
    s += "}}";
    return s;
}

std::string state_json(uint64_t host_ns, const cdm_pose &p) {
    std::string s = "{\"timestamp\":";
    stamp(s, host_ns);
    s += ",\"sequence\":" + std::to_string(p.sequence) + ",\"device_time_us\":" + std::to_string(p.device_time_us) +
         ",\"position_mm\":";
    xyz(s, p.position, 1.0);
    s += ",\"orientation\":";
    quat(s, p.orientation, "wxyz");
    s += ",\"grip_rad\":";
    num(s, p.grip);
    s += ",\"buttons\":" + std::to_string(p.buttons) + ",\"flags\":" + std::to_string(p.flags) + ",\"velocity_mm_s\":";
    // velocity is since 1.1: a struct from an older caller has none.
    const double zero[3] = {0, 0, 0};
    xyz(s, p.struct_size >= offsetof(cdm_pose, velocity) + sizeof p.velocity ? p.velocity : zero, 1.0);
    s += ",\"dropped\":" + std::to_string(p.dropped) + "}";
    return s;
}

int open_mcap_writer(const std::string &path, const uint8_t *info, size_t info_len, const proto::DeviceInfoReport &di,
                     std::unique_ptr<Writer> &out, std::string &err) {
    auto w = std::make_unique<McapWriter>();
    const int rc = w->open(path, info, info_len, di, err);
    if (rc != CDM_OK) return rc;
    out = std::move(w);
    return CDM_OK;
}

int parse_mcap(std::vector<uint8_t> bytes, const std::string &name, replay::File &out, std::string &err) {
    mcap::File m;
    if (!mcap::parse(bytes.data(), bytes.size(), name, m, err)) return CDM_ERR_PARSE;
    replay::File f;
    const mcap::Metadata *device = nullptr;
    for (const auto &md : m.metadata)
        if (md.name == kDeviceMetadata) device = &md;
    if (!device)
        return parse_error(name, 0, "an MCAP file without cdm's \"cdm.device\" metadata (the device-info "
                                    "report): not a cdm recording, or cut before it",
                           err);
    std::string info_hex;
    for (const auto &kv : device->entries)
        if (kv.first == "info_report_hex") info_hex = kv.second;
    if (info_hex.empty() || info_hex.size() % 2 != 0 || info_hex.size() / 2 > replay::kMaxReport)
        return parse_error(name, 0, "cdm.device metadata: info_report_hex of " + std::to_string(info_hex.size()) +
                                        " characters (an even number, 2..2048)",
                           err);
    for (size_t i = 0; i < info_hex.size(); i += 2) {
        const int hi = nibble(info_hex[i]), lo = nibble(info_hex[i + 1]);
        if (hi < 0 || lo < 0)
            return parse_error(name, 0, "cdm.device metadata: info_report_hex has a non-hex character at " +
                                            std::to_string(i),
                               err);
        f.info.push_back(uint8_t(hi * 16 + lo));
    }
    uint16_t report_channel = 0;
    for (const auto &ch : m.channels)
        if (ch.second.topic == kReportTopic && ch.second.message_encoding == kReportEncoding)
            report_channel = ch.first;
    if (report_channel == 0)
        return parse_error(name, 0, std::string("no ") + kReportTopic + " channel with message encoding " +
                                        kReportEncoding + ": nothing to replay",
                           err);
    uint64_t last = 0;
    for (const auto &msg : m.messages) {
        if (msg.channel != report_channel) continue;
        if (msg.length == 0 || msg.length > replay::kMaxReport)
            return parse_error(name, msg.offset, "report of " + std::to_string(msg.length) + " bytes (1..1024)",
                               err);
        if (msg.log_time < last)
            return parse_error(name, msg.offset, "log time goes backwards on " + std::string(kReportTopic) +
                                                     " (report " + std::to_string(f.records.size()) + ")",
                               err);
        last = msg.log_time;
        f.records.push_back(replay::Record{msg.log_time, msg.offset, uint16_t(msg.length)});
    }
    f.truncated_bytes = m.truncated_bytes;
    f.warning = m.warning;
    f.bytes = std::move(bytes);
    out = std::move(f);
    return CDM_OK;
}

} // namespace cdm::recording
