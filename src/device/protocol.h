// The wire protocol of the master (docs/protocol.md is the normative text):
// one parser and one serializer for every report, used by every transport
// (the hidapi backend, the simulated firmware, the replay file) so that a
// byte means the same thing wherever it comes from.
//
// Everything is little-endian and byte-exact; no struct is ever memcpy'd to
// or from the wire (padding and host endianness must not leak into it).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace cdm::proto {

// pid.codes open-source VID; the PID is the project's placeholder pending a
// real allocation (docs/protocol.md).
constexpr uint16_t kVendorId = 0x1209;
constexpr uint16_t kProductId = 0xCD01;

constexpr uint8_t kProtocolVersion = 1;

constexpr uint8_t kInputReportId = 0x01;
constexpr uint8_t kDeviceInfoReportId = 0x02;
constexpr uint8_t kCalHeaderReportId = 0x03;
constexpr uint8_t kCalChunkReportId = 0x04;

// Sizes include the report ID byte (hidapi and hidraw hand it over first).
constexpr size_t kInputReportSize = 64;
constexpr size_t kDeviceInfoReportSize = 128;
constexpr size_t kCalHeaderReportSize = 64;
constexpr size_t kCalChunkReportSize = 64;
constexpr size_t kCalChunkMaxData = 58;
constexpr size_t kCalMaxLength = 16384;

constexpr double kQ14 = 16384.0;

// Status bits of the input report (u16 at offset 2).
enum StatusBit : uint16_t {
    kStatusImuOk = 1u << 0,
    kStatusPotsOk = 1u << 1,
    kStatusHallOk = 1u << 2,
    kStatusCalibrationStored = 1u << 3,
    kStatusOverrun = 1u << 4, // the firmware's report queue overflowed: expect a sequence gap
};

// Why the parser rejected a report. Values are internal (not ABI) but stable
// within a build: the reader thread counts them and names them in the
// handle's error text.
enum class Reject : int {
    None = 0,
    Short,         // fewer bytes than the report's fixed size
    WrongReportId, // first byte is not the expected report ID
    WrongVersion,  // protocol_version byte differs from kProtocolVersion
    QuatZero,      // all four quaternion words are zero (IMU not running)
    QuatNorm,      // | |q| - 1 | > kQuatNormTolerance
    BadValue,      // feature report with a field outside its domain
};
const char *reject_text(Reject r);

// A quaternion quantised to Q14 has per-component rounding error at most
// 0.5/16384 = 3.1e-5, so its norm is within 2 * 3.1e-5 = 6.1e-5 of 1 (four
// components, worst case adds linearly: |dq| <= sqrt(4) * 3.1e-5). A firmware
// normalising in float32 adds ~1e-7. Anything beyond 0.01 (160 times the
// quantisation bound) cannot be a unit quaternion on the wire: it is a
// corrupted or byte-swapped report, and is rejected rather than renormalised
// into a wrong orientation.
constexpr double kQuatNormTolerance = 0.01;

struct InputReport {
    uint8_t protocol_version = kProtocolVersion;
    uint16_t status = 0;
    uint32_t sequence = 0;
    uint64_t device_time_us = 0;
    std::array<uint16_t, 4> pot_adc{};
    std::array<int16_t, 4> quat_q14{}; // w, x, y, z
    uint16_t hall_adc = 0;
    uint16_t buttons = 0;
    bool reserved_nonzero = false; // parse only: a newer firmware filled reserved bytes
};

// Parses an input report (report ID first). `len` may exceed 64 (a longer
// report from a newer firmware): the extra bytes are ignored.
Reject parse_input(const uint8_t *buf, size_t len, InputReport &out);
// Writes exactly kInputReportSize bytes; reserved bytes are zero.
void serialize_input(const InputReport &r, uint8_t *buf);

struct DeviceInfoReport {
    uint8_t protocol_version = kProtocolVersion;
    uint8_t fw_major = 0, fw_minor = 0;
    uint16_t fw_patch = 0;
    uint8_t adc_bits = 16;
    char serial[17] = {}; // 16 on the wire, NUL-padded; +1 for the terminator here
    float report_rate_hz = 1000.0f;
    std::array<float, 4> pot_scale_mm{};
    std::array<float, 4> pot_offset_mm{};
    float a_mm = 0, b_mm = 0, m_mm = 0;
    uint16_t hall_closed = 0, hall_open = 0;
    float grip_open_rad = 0;
};
// Physically sane ranges of the device-info fields (docs/protocol.md,
// "Device info ranges"): a desk-size master has cables of centimetres to a
// metre or two, pots resolving micrometres to a millimetre per count, and a
// report rate between 1 Hz and 100 kHz. A value outside is a corrupt report
// or a broken firmware, and would turn into poses of 1e38 mm.
constexpr double kRateMinHz = 1.0, kRateMaxHz = 100000.0;
constexpr double kPotScaleMinMm = 1e-6, kPotScaleMaxMm = 1.0;   // mm per ADC count
constexpr double kPotOffsetMaxMm = 10000.0;                      // |offset|
constexpr double kGeometryMinMm = 1.0, kGeometryMaxMm = 10000.0; // a, b, m
constexpr double kGripOpenMaxRad = 3.14159265358979323846;      // grip_open_rad in (0, pi]

// Rejects Short, WrongReportId, WrongVersion and BadValue (a field outside
// the ranges above or non-finite, m >= 2a or 2b, hall_open == hall_closed,
// adc_bits outside 1..16, a non-printable serial); `detail` then names the
// field, its value and its range (for the first three: the length, byte 0,
// byte 1 and what they should be).
Reject parse_device_info(const uint8_t *buf, size_t len, DeviceInfoReport &out, std::string *detail);
void serialize_device_info(const DeviceInfoReport &r, uint8_t *buf); // kDeviceInfoReportSize bytes

// Feature 0x03, calibration header.
enum class CalState : uint8_t { Empty = 0, Valid = 1, Writing = 2, CommitFailed = 3 };
enum class CalHeaderOp : uint8_t { None = 0, BeginWrite = 1, Commit = 2, Erase = 3 };

struct CalHeader {
    // GET (device -> host)
    CalState state = CalState::Empty;
    uint32_t length = 0;
    uint32_t crc32 = 0;
    uint32_t capacity = kCalMaxLength;
    uint32_t written = 0; // bytes received since BeginWrite (high-water mark)
    // SET (host -> device); in a GET reply op is None.
    CalHeaderOp op = CalHeaderOp::None;
};
Reject parse_cal_header(const uint8_t *buf, size_t len, CalHeader &out);
void serialize_cal_header(const CalHeader &h, uint8_t *buf); // kCalHeaderReportSize bytes

// Feature 0x04, calibration chunk.
enum class CalChunkOp : uint8_t { Data = 0, SeekRead = 1, WriteData = 2 };
struct CalChunk {
    CalChunkOp op = CalChunkOp::Data; // GET replies carry Data
    uint16_t offset = 0;
    uint8_t length = 0; // <= kCalChunkMaxData
    std::array<uint8_t, kCalChunkMaxData> data{};
};
Reject parse_cal_chunk(const uint8_t *buf, size_t len, CalChunk &out);
void serialize_cal_chunk(const CalChunk &c, uint8_t *buf); // kCalChunkReportSize bytes

// CRC-32 (IEEE 802.3: reflected polynomial 0xEDB88320, init and final xor
// 0xFFFFFFFF), zlib's crc32; crc32("123456789") = 0xCBF43926. Pass the
// previous result as `crc` to continue over several pieces.
uint32_t crc32(const uint8_t *data, size_t len, uint32_t crc = 0);

// The HID report descriptor the firmware presents (docs/protocol.md lists it
// byte by byte with comments). The simulated firmware hands it out too.
extern const uint8_t kReportDescriptor[];
extern const size_t kReportDescriptorSize;

// Little-endian helpers, shared by the replay file format.
inline void put_u16(uint8_t *p, uint16_t v) {
    p[0] = uint8_t(v);
    p[1] = uint8_t(v >> 8);
}
inline void put_u32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}
inline void put_u64(uint8_t *p, uint64_t v) {
    for (int i = 0; i < 8; ++i) p[i] = uint8_t(v >> (8 * i));
}
inline uint16_t get_u16(const uint8_t *p) { return uint16_t(p[0] | (p[1] << 8)); }
inline uint32_t get_u32(const uint8_t *p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
inline uint64_t get_u64(const uint8_t *p) {
    return uint64_t(get_u32(p)) | uint64_t(get_u32(p + 4)) << 32;
}
void put_f32(uint8_t *p, float v);
float get_f32(const uint8_t *p);

} // namespace cdm::proto
