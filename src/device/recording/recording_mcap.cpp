#include "device/recording/recording_mcap.h"

#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "device/protocol.h"
#include "io/mcap.h"

namespace cdm::recording {

// The ROS 2 message definitions, in rosbag2's layout: the type's own text,
// then each type it uses after a line of 80 '=' and "MSG: pkg/Type".
const char *const kPoseDefinition = R"msg(std_msgs/Header header
geometry_msgs/Pose pose
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Pose
geometry_msgs/Point position
geometry_msgs/Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
)msg";

// examples/ros2/cdm_msgs/msg/State.msg, then its dependencies.
const char *const kStateDefinition = R"msg(# One cdm_pose beside the pose of /cdm/pose in a cdm MCAP recording
# (docs/recording.md): what a geometry_msgs/PoseStamped does not carry.
# Every 10 ms of device time, and at every report where buttons, flags or
# dropped change.
# cdm writes it from this file's text (tests/cli/test_mcap.py compares them).
# Wall-clock time of the report (CLOCK_REALTIME), the recording's log time.
builtin_interfaces/Time stamp
# The device clock at sampling, microseconds.
uint64 device_time_us
# Jaw opening, radians, 0 = closed.
float64 grip_rad
# Filtered velocity of the holder, mm/s, device frame.
geometry_msgs/Vector3 velocity_mm_s
# The device's report counter.
uint32 sequence
# cdm_pose_flag bits (include/cdm/cdm.h).
uint32 flags
# Reports lost so far.
uint32 dropped
# cdm_button bits: 1 clutch, 2 aux, 4 mark.
uint8 buttons
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
)msg";

// examples/ros2/cdm_msgs/msg/Rejected.msg, then its dependency.
const char *const kRejectedDefinition = R"msg(# A report the reader discarded, in a cdm MCAP recording (docs/recording.md):
# its bytes are on /cdm/report at the same log time, so a replay discards it
# again; this says why.
# cdm writes it from this file's text (tests/cli/test_mcap.py compares them).
# Wall-clock time of the report (CLOCK_REALTIME), the recording's log time.
builtin_interfaces/Time stamp
# 1: the protocol parser refused it; 2: a duplicate or a late report.
uint8 kind
# Why, in words.
string reason
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
)msg";

namespace {

// CDR as ROS 2 serialises (XCDR1, little endian): a 4-byte encapsulation
// header, then each primitive aligned to its size counted from after it.
class Cdr {
public:
    Cdr() : b_("\x00\x01\x00\x00", 4) {}
    template <class T> void put(T v) {
        align(sizeof v);
        uint8_t raw[sizeof v];
        std::memcpy(raw, &v, sizeof v); // x86_64 and aarch64 are little endian: the bytes as they are
        b_.append(reinterpret_cast<const char *>(raw), sizeof v);
    }
    void str(const char *s) {
        const size_t n = std::strlen(s);
        put(uint32_t(n + 1)); // the length counts the terminating NUL
        b_.append(s, n + 1);
    }
    // builtin_interfaces/Time from ns since the epoch.
    void time(uint64_t ns) {
        put(int32_t(ns / 1000000000u));
        put(uint32_t(ns % 1000000000u));
    }
    std::string take() { return std::move(b_); }

private:
    void align(size_t n) {
        while ((b_.size() - 4) % n) b_.push_back('\0');
    }
    std::string b_;
};
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "CDR little endian written as native bytes");

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

uint64_t clock_ns(clockid_t id) {
    timespec ts{};
    clock_gettime(id, &ts);
    return uint64_t(ts.tv_sec) * 1000000000u + uint64_t(ts.tv_nsec);
}

class McapWriter final : public Writer {
public:
    int open(const std::string &path, const uint8_t *info, size_t info_len, const proto::DeviceInfoReport &di,
             mcap::Compression compression, std::string &err) {
        const std::string version = std::to_string(CDM_VERSION_MAJOR) + "." + std::to_string(CDM_VERSION_MINOR) +
                                    "." + std::to_string(CDM_VERSION_PATCH);
        // Both clocks read back to back: wall-clock log times that keep the
        // monotonic clock's steps (an NTP jump during a recording moves none).
        // A wall clock behind the monotonic one (never set) keeps monotonic times.
        const uint64_t mono = clock_ns(CLOCK_MONOTONIC), real = clock_ns(CLOCK_REALTIME);
        offset_ = real > mono ? real - mono : 0;
        // No well-known profile fits (ros2 needs CDR on every channel, the
        // raw reports are not): the profile names cdm's own layout.
        if (!w_.open(path, "cdm", "libcdm " + version, err, compression)) return CDM_ERR_IO;
        const uint16_t report_schema = w_.add_schema(kReportEncoding, "", "");
        report_ = w_.add_channel(report_schema, kReportTopic, kReportEncoding,
                                 {{"layout", "docs/protocol.md, input report 0x01, report ID first"},
                                  {"protocol_version", std::to_string(di.protocol_version)}});
        pose_ = w_.add_channel(w_.add_schema(kPoseSchema, "ros2msg", kPoseDefinition), kPoseTopic, "cdr");
        state_ = w_.add_channel(w_.add_schema(kStateSchema, "ros2msg", kStateDefinition), kStateTopic, "cdr");
        char rate[32];
        std::snprintf(rate, sizeof rate, "%g", double(di.report_rate_hz));
        const mcap::StringMap entries = {
            {"info_report_hex", hex(info, info_len)},
            {"serial", di.serial},
            {"firmware", std::to_string(di.fw_major) + "." + std::to_string(di.fw_minor) + "." +
                             std::to_string(di.fw_patch)},
            {"protocol_version", std::to_string(di.protocol_version)},
            {"report_rate_hz", rate},
            {kClockOffsetKey, std::to_string(offset_)},
            {"time", "log_time = host receipt time (CLOCK_MONOTONIC) + clock_offset_ns: ns since the epoch"},
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
        if (host_ns > UINT64_MAX - offset_) {
            err = "host time " + std::to_string(host_ns) + " ns: past what a wall-clock log time holds";
            return CDM_ERR_INVALID_ARG;
        }
        const uint64_t t = host_ns + offset_;
        if (!w_.write_message(report_, t, report, len, err)) return CDM_ERR_IO;
        ++reports_;
        last_ns_ = host_ns;
        if (!pose) return CDM_OK;
        const std::string p = pose_cdr(t, *pose);
        if (!w_.write_message(pose_, t, reinterpret_cast<const uint8_t *>(p.data()), p.size(), err))
            return CDM_ERR_IO;
        if (!state_due(*pose)) return CDM_OK;
        const std::string s = state_cdr(t, *pose);
        if (!w_.write_message(state_, t, reinterpret_cast<const uint8_t *>(s.data()), s.size(), err))
            return CDM_ERR_IO;
        return CDM_OK;
    }

    int write_rejected(uint64_t host_ns, const uint8_t *report, size_t len, const char *kind, const char *reason,
                       std::string &err) override {
        if (int rc = write(host_ns, report, len, nullptr, err); rc != CDM_OK) return rc;
        // The channel appears with the first rejected report: a clean
        // recording has none.
        if (!rejected_)
            rejected_ = w_.add_channel(w_.add_schema(kRejectedSchema, "ros2msg", kRejectedDefinition),
                                       kRejectedTopic, "cdr");
        Cdr c;
        c.time(host_ns + offset_);
        c.put(uint8_t(std::strcmp(kind, "malformed") == 0 ? 1 : 2));
        c.str(reason);
        const std::string body = c.take();
        return w_.write_message(rejected_, host_ns + offset_, reinterpret_cast<const uint8_t *>(body.data()),
                                body.size(), err)
                   ? CDM_OK
                   : CDM_ERR_IO;
    }

    int close(std::string &err) override { return w_.close(err) ? CDM_OK : CDM_ERR_IO; }
    uint64_t reports() const override { return reports_; }

private:
    // kStatePeriodUs of device time since the last state, or buttons, flags
    // or dropped changed (an event is never thinned out), or the device
    // clock went back (a reset).
    bool state_due(const cdm_pose &p) {
        const bool due = !states_ || p.buttons != last_state_.buttons || p.flags != last_state_.flags ||
                         p.dropped != last_state_.dropped || p.device_time_us < last_state_.device_time_us ||
                         p.device_time_us - last_state_.device_time_us >= kStatePeriodUs;
        if (due) {
            last_state_ = p;
            ++states_;
        }
        return due;
    }
    mcap::Writer w_;
    cdm_pose last_state_{};
    uint64_t states_ = 0;
    uint16_t report_ = 0, pose_ = 0, state_ = 0, rejected_ = 0;
    uint64_t reports_ = 0;
    uint64_t last_ns_ = 0; // the last report's host time
    uint64_t offset_ = 0;  // CLOCK_REALTIME - CLOCK_MONOTONIC at open
};

int parse_error(const std::string &name, size_t offset, const std::string &what, std::string &err) {
    err = name + ": byte " + std::to_string(offset) + ": " + what;
    return CDM_ERR_PARSE;
}

const std::string *entry(const mcap::Metadata &md, const char *key) {
    for (const auto &kv : md.entries)
        if (kv.first == key) return &kv.second;
    return nullptr;
}

// The device-info report and the clock offset of the cdm.device metadata.
int read_device(const mcap::File &m, const std::string &name, replay::File &f, uint64_t &offset, std::string &err) {
    const mcap::Metadata *device = nullptr;
    for (const auto &md : m.metadata)
        if (md.name == kDeviceMetadata) device = &md;
    if (!device)
        return parse_error(name, 0, "an MCAP file without cdm's \"cdm.device\" metadata (the device-info "
                                    "report): not a cdm recording, or cut before it",
                           err);
    const std::string *hexp = entry(*device, "info_report_hex");
    const std::string info_hex = hexp ? *hexp : "";
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
    offset = 0;
    if (const std::string *o = entry(*device, kClockOffsetKey)) {
        const auto r = std::from_chars(o->data(), o->data() + o->size(), offset);
        if (r.ec != std::errc() || r.ptr != o->data() + o->size())
            return parse_error(name, 0, std::string("cdm.device metadata: ") + kClockOffsetKey + " \"" +
                                            o->substr(0, 32) + "\" is not a count of nanoseconds",
                               err);
    }
    return CDM_OK;
}

} // namespace

void append_number(std::string &s, double v) {
    char b[32];
    const auto r = std::to_chars(b, b + sizeof b, v, std::chars_format::general, 17);
    s.append(b, r.ptr);
}

std::string pose_cdr(uint64_t wall_ns, const cdm_pose &p) {
    Cdr c;
    c.time(wall_ns);
    c.str(kPoseFrame);
    for (int k = 0; k < 3; ++k) c.put(p.position[k] * 1e-3); // mm to m: one rounding
    // cdm_pose is w,x,y,z; ROS x,y,z,w.
    for (int k : {1, 2, 3, 0}) c.put(p.orientation[k]);
    return c.take();
}

std::string state_cdr(uint64_t wall_ns, const cdm_pose &p) {
    Cdr c;
    c.time(wall_ns);
    c.put(uint64_t(p.device_time_us));
    c.put(double(p.grip));
    // velocity is since 1.1: a struct from an older caller has none.
    const bool has_v = p.struct_size >= offsetof(cdm_pose, velocity) + sizeof p.velocity;
    for (int k = 0; k < 3; ++k) c.put(has_v ? p.velocity[k] : 0.0);
    c.put(uint32_t(p.sequence));
    c.put(uint32_t(p.flags));
    c.put(uint32_t(p.dropped));
    c.put(uint8_t(p.buttons));
    return c.take();
}

int open_mcap_writer(const std::string &path, const uint8_t *info, size_t info_len, const proto::DeviceInfoReport &di,
                     const std::string &compression, std::unique_ptr<Writer> &out, std::string &err) {
    mcap::Compression comp = mcap::Compression::Zstd;
    if (!compression.empty() && !mcap::parse_compression(compression, comp)) {
        err = "MCAP compression \"" + compression + "\" is not one of zstd, lz4, none";
        return CDM_ERR_INVALID_ARG;
    }
    auto w = std::make_unique<McapWriter>();
    const int rc = w->open(path, info, info_len, di, comp, err);
    if (rc != CDM_OK) return rc;
    out = std::move(w);
    return CDM_OK;
}

int parse_mcap(std::vector<uint8_t> bytes, const std::string &name, replay::File &out, std::string &err) {
    mcap::File m;
    if (!mcap::parse(bytes.data(), bytes.size(), name, m, err)) return CDM_ERR_PARSE;
    replay::File f;
    uint64_t offset = 0;
    if (int rc = read_device(m, name, f, offset, err); rc != CDM_OK) return rc;
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
        if (msg.log_time < offset)
            return parse_error(name, msg.offset, "log time " + std::to_string(msg.log_time) + " is before " +
                                                     kClockOffsetKey + " " + std::to_string(offset),
                               err);
        last = msg.log_time;
        // The reports copied out: a compressed chunk's bytes are not the file's.
        f.records.push_back(replay::Record{msg.log_time - offset, f.bytes.size(), uint16_t(msg.length)});
        f.bytes.insert(f.bytes.end(), msg.data, msg.data + msg.length);
    }
    f.truncated_bytes = m.truncated_bytes;
    f.warning = m.warning;
    out = std::move(f);
    return CDM_OK;
}

} // namespace cdm::recording
