#include "device/protocol.h"

#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <cstring>

namespace cdm::proto {

// A vendor-defined usage page: the OS binds no input driver (the master must
// not move the mouse), and hidraw hands the bytes to libcdm unchanged.
// Table with comments: docs/protocol.md.
const uint8_t kReportDescriptor[] = {
    0x06, 0x00, 0xFF, // Usage Page (Vendor Defined 0xFF00)
    0x09, 0x01,       // Usage (0x01): haptic master
    0xA1, 0x01,       // Collection (Application)
    0x15, 0x00,       //   Logical Minimum (0)
    0x26, 0xFF, 0x00, //   Logical Maximum (255)
    0x75, 0x08,       //   Report Size (8 bits)
    0x85, 0x01,       //   Report ID (1): input report
    0x09, 0x01,       //   Usage (0x01)
    0x95, 0x3F,       //   Report Count (63)
    0x81, 0x02,       //   Input (Data, Variable, Absolute)
    0x85, 0x02,       //   Report ID (2): device info
    0x09, 0x02,       //   Usage (0x02)
    0x95, 0x7F,       //   Report Count (127)
    0xB1, 0x02,       //   Feature (Data, Variable, Absolute)
    0x85, 0x03,       //   Report ID (3): calibration header
    0x09, 0x03,       //   Usage (0x03)
    0x95, 0x3F,       //   Report Count (63)
    0xB1, 0x02,       //   Feature (Data, Variable, Absolute)
    0x85, 0x04,       //   Report ID (4): calibration chunk
    0x09, 0x04,       //   Usage (0x04)
    0x95, 0x3F,       //   Report Count (63)
    0xB1, 0x02,       //   Feature (Data, Variable, Absolute)
    0xC0,             // End Collection
};
const size_t kReportDescriptorSize = sizeof(kReportDescriptor);

const char *reject_text(Reject r) {
    switch (r) {
    case Reject::None: return "accepted";
    case Reject::Short: return "short report";
    case Reject::WrongReportId: return "wrong report ID";
    case Reject::WrongVersion: return "wrong protocol version";
    case Reject::QuatZero: return "all-zero quaternion (IMU not running)";
    case Reject::QuatNorm: return "quaternion norm far from 1";
    case Reject::BadValue: return "field value out of range";
    }
    return "unknown rejection";
}

void put_f32(uint8_t *p, float v) {
    uint32_t u;
    static_assert(sizeof u == sizeof v, "float32 is 4 bytes");
    std::memcpy(&u, &v, 4);
    put_u32(p, u);
}

float get_f32(const uint8_t *p) {
    uint32_t u = get_u32(p);
    float v;
    std::memcpy(&v, &u, 4);
    return v;
}

Reject parse_input(const uint8_t *buf, size_t len, InputReport &out) {
    if (buf == nullptr || len < kInputReportSize) return Reject::Short;
    if (buf[0] != kInputReportId) return Reject::WrongReportId;
    if (buf[1] != kProtocolVersion) return Reject::WrongVersion;
    InputReport r;
    r.protocol_version = buf[1];
    r.status = get_u16(buf + 2);
    r.sequence = get_u32(buf + 4);
    r.device_time_us = get_u64(buf + 8);
    for (int i = 0; i < 4; ++i) r.pot_adc[i] = get_u16(buf + 16 + 2 * i);
    double n2 = 0;
    bool all_zero = true;
    for (int i = 0; i < 4; ++i) {
        r.quat_q14[i] = int16_t(get_u16(buf + 24 + 2 * i));
        const double c = r.quat_q14[i] / kQ14;
        n2 += c * c;
        all_zero = all_zero && r.quat_q14[i] == 0;
    }
    if (all_zero) return Reject::QuatZero;
    if (std::fabs(std::sqrt(n2) - 1.0) > kQuatNormTolerance) return Reject::QuatNorm;
    r.hall_adc = get_u16(buf + 32);
    r.buttons = get_u16(buf + 34);
    for (size_t i = 36; i < kInputReportSize; ++i) r.reserved_nonzero = r.reserved_nonzero || buf[i] != 0;
    out = r;
    return Reject::None;
}

void serialize_input(const InputReport &r, uint8_t *buf) {
    std::memset(buf, 0, kInputReportSize);
    buf[0] = kInputReportId;
    buf[1] = r.protocol_version;
    put_u16(buf + 2, r.status);
    put_u32(buf + 4, r.sequence);
    put_u64(buf + 8, r.device_time_us);
    for (int i = 0; i < 4; ++i) put_u16(buf + 16 + 2 * i, r.pot_adc[i]);
    for (int i = 0; i < 4; ++i) put_u16(buf + 24 + 2 * i, uint16_t(r.quat_q14[i]));
    put_u16(buf + 32, r.hall_adc);
    put_u16(buf + 34, r.buttons);
}

namespace {
Reject bad(std::string *detail, const std::string &what) {
    if (detail) *detail = what;
    return Reject::BadValue;
}
bool positive_finite(float v) { return std::isfinite(v) && v > 0; }
bool in_range(float v, double lo, double hi) { return std::isfinite(v) && double(v) >= lo && double(v) <= hi; }
std::string hex_byte(uint8_t b) {
    char t[8];
    std::snprintf(t, sizeof t, "0x%02X", unsigned(b));
    return t;
}
std::string range_text(const std::string &field, float v, double lo, double hi) {
    char b[200];
    std::snprintf(b, sizeof b, "%s = %g outside [%g, %g]", field.c_str(), double(v), lo, hi);
    return b;
}
} // namespace

Reject parse_device_info(const uint8_t *buf, size_t len, DeviceInfoReport &out, std::string *detail) {
    if (buf == nullptr || len < kDeviceInfoReportSize) {
        if (detail) *detail = std::to_string(buf ? len : 0) + " bytes, a device-info report has " +
                              std::to_string(kDeviceInfoReportSize);
        return Reject::Short;
    }
    if (buf[0] != kDeviceInfoReportId) {
        if (detail) *detail = "byte 0 is " + hex_byte(buf[0]) + ", a device-info report starts with " +
                              hex_byte(kDeviceInfoReportId);
        return Reject::WrongReportId;
    }
    if (buf[1] != kProtocolVersion) {
        if (detail) *detail = "byte 1 is " + std::to_string(buf[1]) + ", this library speaks protocol " +
                              std::to_string(kProtocolVersion);
        return Reject::WrongVersion;
    }
    DeviceInfoReport r;
    r.protocol_version = buf[1];
    r.fw_major = buf[2];
    r.fw_minor = buf[3];
    r.fw_patch = get_u16(buf + 4);
    r.adc_bits = buf[6];
    if (r.adc_bits < 1 || r.adc_bits > 16) return bad(detail, "adc_bits (byte 6) must be 1..16, got " + std::to_string(r.adc_bits));
    bool ended = false;
    for (int i = 0; i < 16; ++i) {
        const uint8_t c = buf[8 + i];
        if (c == 0) {
            ended = true;
        } else if (ended || c < 0x20 || c > 0x7E) {
            // NUL padding must be trailing, characters printable ASCII:
            // the serial ends up in URIs and file names.
            return bad(detail, "serial (bytes 8..23) is not NUL-padded printable ASCII");
        }
        r.serial[i] = char(c);
    }
    r.serial[16] = 0;
    r.report_rate_hz = get_f32(buf + 24);
    if (!in_range(r.report_rate_hz, kRateMinHz, kRateMaxHz))
        return bad(detail, range_text("report_rate_hz (bytes 24..27)", r.report_rate_hz, kRateMinHz, kRateMaxHz));
    for (int i = 0; i < 4; ++i) {
        const std::string k = "[" + std::to_string(i) + "]";
        r.pot_scale_mm[i] = get_f32(buf + 28 + 4 * i);
        r.pot_offset_mm[i] = get_f32(buf + 44 + 4 * i);
        if (!in_range(r.pot_scale_mm[i], kPotScaleMinMm, kPotScaleMaxMm))
            return bad(detail, range_text("pot_scale_mm" + k, r.pot_scale_mm[i], kPotScaleMinMm, kPotScaleMaxMm));
        if (!in_range(r.pot_offset_mm[i], -kPotOffsetMaxMm, kPotOffsetMaxMm))
            return bad(detail, range_text("pot_offset_mm" + k, r.pot_offset_mm[i], -kPotOffsetMaxMm, kPotOffsetMaxMm));
    }
    r.a_mm = get_f32(buf + 60);
    r.b_mm = get_f32(buf + 64);
    r.m_mm = get_f32(buf + 68);
    const char *names[3] = {"a_mm (bytes 60..63)", "b_mm (bytes 64..67)", "m_mm (bytes 68..71)"};
    const float geo[3] = {r.a_mm, r.b_mm, r.m_mm};
    for (int i = 0; i < 3; ++i)
        if (!in_range(geo[i], kGeometryMinMm, kGeometryMaxMm))
            return bad(detail, range_text(names[i], geo[i], kGeometryMinMm, kGeometryMaxMm));
    if (r.m_mm >= 2 * r.a_mm || r.m_mm >= 2 * r.b_mm)
        return bad(detail, "geometry a,b,m (bytes 60..71) must have m < 2a and m < 2b");
    r.hall_closed = get_u16(buf + 72);
    r.hall_open = get_u16(buf + 74);
    if (r.hall_closed == r.hall_open) return bad(detail, "hall_closed equals hall_open (bytes 72..75)");
    r.grip_open_rad = get_f32(buf + 76);
    if (!positive_finite(r.grip_open_rad) || double(r.grip_open_rad) > kGripOpenMaxRad)
        return bad(detail, range_text("grip_open_rad (bytes 76..79)", r.grip_open_rad, 0, kGripOpenMaxRad) +
                               " (0 excluded)");
    out = r;
    return Reject::None;
}

void serialize_device_info(const DeviceInfoReport &r, uint8_t *buf) {
    std::memset(buf, 0, kDeviceInfoReportSize);
    buf[0] = kDeviceInfoReportId;
    buf[1] = r.protocol_version;
    buf[2] = r.fw_major;
    buf[3] = r.fw_minor;
    put_u16(buf + 4, r.fw_patch);
    buf[6] = r.adc_bits;
    for (int i = 0; i < 16 && r.serial[i]; ++i) buf[8 + i] = uint8_t(r.serial[i]);
    put_f32(buf + 24, r.report_rate_hz);
    for (int i = 0; i < 4; ++i) {
        put_f32(buf + 28 + 4 * i, r.pot_scale_mm[i]);
        put_f32(buf + 44 + 4 * i, r.pot_offset_mm[i]);
    }
    put_f32(buf + 60, r.a_mm);
    put_f32(buf + 64, r.b_mm);
    put_f32(buf + 68, r.m_mm);
    put_u16(buf + 72, r.hall_closed);
    put_u16(buf + 74, r.hall_open);
    put_f32(buf + 76, r.grip_open_rad);
}

Reject parse_cal_header(const uint8_t *buf, size_t len, CalHeader &out) {
    if (buf == nullptr || len < kCalHeaderReportSize) return Reject::Short;
    if (buf[0] != kCalHeaderReportId) return Reject::WrongReportId;
    if (buf[1] > uint8_t(CalHeaderOp::Erase) || buf[2] > uint8_t(CalState::CommitFailed)) return Reject::BadValue;
    CalHeader h;
    h.op = CalHeaderOp(buf[1]);
    h.state = CalState(buf[2]);
    h.length = get_u32(buf + 4);
    h.crc32 = get_u32(buf + 8);
    h.capacity = get_u32(buf + 12);
    h.written = get_u32(buf + 16);
    out = h;
    return Reject::None;
}

void serialize_cal_header(const CalHeader &h, uint8_t *buf) {
    std::memset(buf, 0, kCalHeaderReportSize);
    buf[0] = kCalHeaderReportId;
    buf[1] = uint8_t(h.op);
    buf[2] = uint8_t(h.state);
    put_u32(buf + 4, h.length);
    put_u32(buf + 8, h.crc32);
    put_u32(buf + 12, h.capacity);
    put_u32(buf + 16, h.written);
}

Reject parse_cal_chunk(const uint8_t *buf, size_t len, CalChunk &out) {
    if (buf == nullptr || len < kCalChunkReportSize) return Reject::Short;
    if (buf[0] != kCalChunkReportId) return Reject::WrongReportId;
    if (buf[1] > uint8_t(CalChunkOp::WriteData) || buf[4] > kCalChunkMaxData) return Reject::BadValue;
    CalChunk c;
    c.op = CalChunkOp(buf[1]);
    c.offset = get_u16(buf + 2);
    c.length = buf[4];
    std::memcpy(c.data.data(), buf + 6, kCalChunkMaxData);
    out = c;
    return Reject::None;
}

void serialize_cal_chunk(const CalChunk &c, uint8_t *buf) {
    std::memset(buf, 0, kCalChunkReportSize);
    buf[0] = kCalChunkReportId;
    buf[1] = uint8_t(c.op);
    put_u16(buf + 2, c.offset);
    buf[4] = c.length;
    // Bytes past `length` go out as zero so that a report is a function of
    // its meaning (golden vectors, replay files compare byte for byte).
    std::memcpy(buf + 6, c.data.data(), c.length <= kCalChunkMaxData ? c.length : kCalChunkMaxData);
}

uint32_t crc32(const uint8_t *data, size_t len, uint32_t crc) {
    if (len == 0) return crc; // zlib answers its initial value for a null buffer
    return uint32_t(::crc32_z(crc, data, len));
}

} // namespace cdm::proto
