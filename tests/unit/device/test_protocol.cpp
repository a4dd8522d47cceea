// Protocol: golden byte vectors, round trips, and every rejection kind.
//
// The golden vectors (tests/data/protocol/*.hex) were generated once from
// the byte tables in docs/protocol.md by the hand-built arrays below (run
// with CDM_WRITE_GOLDEN=1), not by the serializer: the test then holds the
// serializer and the parser to bytes neither of them produced.

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "device/protocol.h"
#include "test_util.h"

// cmocka last: its fail() macro must not meet the C++ headers.
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
extern "C" {
#include <cmocka.h>
}

using namespace cdm::proto;

namespace {

const std::string kData = CDM_TEST_DATA_DIR "/protocol/";

// Input report, field by field as docs/protocol.md lists it.
const std::vector<uint8_t> kInputBytes = {
    0x01,                                           // [0] report ID
    0x01,                                           // [1] protocol version 1
    0x0F, 0x00,                                     // [2..3] status: imu, pots, hall, calibration stored
    0x78, 0x56, 0x34, 0x12,                         // [4..7] sequence 0x12345678
    0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01, // [8..15] device time 0x0102030405060708 us
    0xE8, 0x03,                                     // [16..17] pot 1: 1000
    0x20, 0x4E,                                     // [18..19] pot 2: 20000
    0x30, 0x75,                                     // [20..21] pot 3: 30000
    0xFF, 0xFF,                                     // [22..23] pot 4: 65535
    0x00, 0x20,                                     // [24..25] w =  8192 (0.5)
    0x00, 0xE0,                                     // [26..27] x = -8192
    0x00, 0x20,                                     // [28..29] y =  8192
    0x00, 0xE0,                                     // [30..31] z = -8192
    0x28, 0x0A,                                     // [32..33] hall 2600
    0x05, 0x00,                                     // [34..35] buttons: clutch + mark
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,       // [36..63] reserved
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
};

InputReport input_values() {
    InputReport r;
    r.status = 0x000F;
    r.sequence = 0x12345678u;
    r.device_time_us = 0x0102030405060708ull;
    r.pot_adc = {1000, 20000, 30000, 65535};
    r.quat_q14 = {8192, -8192, 8192, -8192};
    r.hall_adc = 2600;
    r.buttons = 5;
    return r;
}

const std::vector<uint8_t> kInfoBytes = [] {
    std::vector<uint8_t> b = {
        0x02,                                           // [0] report ID
        0x01,                                           // [1] protocol version
        0x01, 0x02, 0x03, 0x00,                         // [2] fw major 1, [3] minor 2, [4..5] patch 3
        0x10,                                           // [6] adc_bits 16
        0x00,                                           // [7] reserved
        'C', 'D', 'M', '-', '0', '0', '4', '2', 0, 0, 0, 0, 0, 0, 0, 0, // [8..23] serial
        0x00, 0x00, 0x7A, 0x44,                         // [24..27] report rate 1000.0f
        0x0A, 0xD7, 0x23, 0x3C,                         // [28..31] pot 1 scale 0.01f
        0x0A, 0xD7, 0xA3, 0x3C,                         // [32..35] pot 2 scale 0.02f
        0x0A, 0xD7, 0xA3, 0x3B,                         // [36..39] pot 3 scale 0.005f
        0x0A, 0xD7, 0x23, 0x3C,                         // [40..43] pot 4 scale 0.01f
        0x00, 0x00, 0x00, 0x00,                         // [44..47] pot 1 offset 0
        0x00, 0x00, 0xC0, 0x3F,                         // [48..51] pot 2 offset 1.5
        0x00, 0x00, 0x00, 0xC0,                         // [52..55] pot 3 offset -2.0
        0x00, 0x00, 0x80, 0x3E,                         // [56..59] pot 4 offset 0.25
        0x00, 0x00, 0x16, 0x43,                         // [60..63] a 150.0
        0x00, 0x00, 0xF0, 0x42,                         // [64..67] b 120.0
        0x00, 0x00, 0xF0, 0x41,                         // [68..71] m 30.0
        0x28, 0x0A,                                     // [72..73] hall closed 2600
        0x78, 0x05,                                     // [74..75] hall open 1400
        0x9A, 0x99, 0x19, 0x3F,                         // [76..79] grip open 0.6f rad
    };
    b.resize(128, 0); // [80..127] reserved
    return b;
}();

DeviceInfoReport info_values() {
    DeviceInfoReport r;
    r.fw_major = 1;
    r.fw_minor = 2;
    r.fw_patch = 3;
    r.adc_bits = 16;
    std::strcpy(r.serial, "CDM-0042");
    r.report_rate_hz = 1000.0f;
    r.pot_scale_mm = {0.01f, 0.02f, 0.005f, 0.01f};
    r.pot_offset_mm = {0.0f, 1.5f, -2.0f, 0.25f};
    r.a_mm = 150.0f;
    r.b_mm = 120.0f;
    r.m_mm = 30.0f;
    r.hall_closed = 2600;
    r.hall_open = 1400;
    r.grip_open_rad = 0.6f;
    return r;
}

const std::vector<uint8_t> kCalHeaderBytes = [] {
    std::vector<uint8_t> b = {
        0x03,                   // [0] report ID
        0x00,                   // [1] op: none (a GET reply)
        0x01,                   // [2] state: valid
        0x00,                   // [3] reserved
        0xD2, 0x04, 0x00, 0x00, // [4..7] length 1234
        0x26, 0x39, 0xF4, 0xCB, // [8..11] crc32 0xCBF43926
        0x00, 0x40, 0x00, 0x00, // [12..15] capacity 16384
        0xD2, 0x04, 0x00, 0x00, // [16..19] written 1234
    };
    b.resize(64, 0);
    return b;
}();

const std::vector<uint8_t> kCalChunkBytes = [] {
    std::vector<uint8_t> b = {
        0x04,                    // [0] report ID
        0x02,                    // [1] op: write data
        0x02, 0x01,              // [2..3] offset 0x0102
        0x05,                    // [4] length 5
        0x00,                    // [5] reserved
        'h', 'e', 'l', 'l', 'o', // [6..] data
    };
    b.resize(64, 0);
    return b;
}();

void check_golden(const char *file, const char *what, const std::vector<uint8_t> &hand) {
    const std::string path = kData + file;
    if (std::getenv("CDM_WRITE_GOLDEN")) assert_true(cdm_test::write_hex(path, what, hand));
    std::vector<uint8_t> golden;
    if (!cdm_test::read_hex(path, golden)) fail_msg("cannot read golden vector %s", path.c_str());
    assert_int_equal(golden.size(), hand.size());
    assert_memory_equal(golden.data(), hand.data(), hand.size());
}

void test_input_golden(void **) {
    check_golden("input_report.hex", "input report 0x01", kInputBytes);
    uint8_t out[kInputReportSize];
    serialize_input(input_values(), out);
    assert_memory_equal(out, kInputBytes.data(), kInputReportSize);
    InputReport r;
    assert_int_equal(int(parse_input(kInputBytes.data(), kInputBytes.size(), r)), int(Reject::None));
    const InputReport e = input_values();
    assert_int_equal(r.status, e.status);
    assert_int_equal(r.sequence, e.sequence);
    assert_true(r.device_time_us == e.device_time_us);
    for (int i = 0; i < 4; ++i) {
        assert_int_equal(r.pot_adc[i], e.pot_adc[i]);
        assert_int_equal(r.quat_q14[i], e.quat_q14[i]);
    }
    assert_int_equal(r.hall_adc, e.hall_adc);
    assert_int_equal(r.buttons, e.buttons);
    assert_false(r.reserved_nonzero);
}

void test_info_golden(void **) {
    check_golden("device_info.hex", "feature report 0x02, device info", kInfoBytes);
    uint8_t out[kDeviceInfoReportSize];
    serialize_device_info(info_values(), out);
    assert_memory_equal(out, kInfoBytes.data(), kDeviceInfoReportSize);
    DeviceInfoReport r;
    std::string detail;
    assert_int_equal(int(parse_device_info(kInfoBytes.data(), kInfoBytes.size(), r, &detail)), int(Reject::None));
    const DeviceInfoReport e = info_values();
    assert_string_equal(r.serial, e.serial);
    assert_int_equal(r.fw_major, 1);
    assert_int_equal(r.fw_minor, 2);
    assert_int_equal(r.fw_patch, 3);
    for (int i = 0; i < 4; ++i) {
        assert_true(r.pot_scale_mm[i] == e.pot_scale_mm[i]);
        assert_true(r.pot_offset_mm[i] == e.pot_offset_mm[i]);
    }
    assert_true(r.a_mm == 150.0f && r.b_mm == 120.0f && r.m_mm == 30.0f);
    assert_int_equal(r.hall_closed, 2600);
    assert_int_equal(r.hall_open, 1400);
    assert_true(r.grip_open_rad == 0.6f);
}

void test_cal_golden(void **) {
    check_golden("cal_header.hex", "feature report 0x03, calibration header (GET reply)", kCalHeaderBytes);
    check_golden("cal_chunk.hex", "feature report 0x04, calibration chunk (SET write-data)", kCalChunkBytes);
    CalHeader h;
    h.state = CalState::Valid;
    h.length = 1234;
    h.crc32 = 0xCBF43926u;
    h.capacity = 16384;
    h.written = 1234;
    uint8_t out[64];
    serialize_cal_header(h, out);
    assert_memory_equal(out, kCalHeaderBytes.data(), 64);
    CalHeader hp;
    assert_int_equal(int(parse_cal_header(out, 64, hp)), int(Reject::None));
    assert_int_equal(hp.length, 1234);
    assert_int_equal(int(hp.state), int(CalState::Valid));
    CalChunk c;
    c.op = CalChunkOp::WriteData;
    c.offset = 0x0102;
    c.length = 5;
    std::memcpy(c.data.data(), "hello", 5);
    serialize_cal_chunk(c, out);
    assert_memory_equal(out, kCalChunkBytes.data(), 64);
    CalChunk cp;
    assert_int_equal(int(parse_cal_chunk(out, 64, cp)), int(Reject::None));
    assert_int_equal(cp.offset, 0x0102);
    assert_int_equal(cp.length, 5);
    assert_memory_equal(cp.data.data(), "hello", 5);
    // A length past the 58 data bytes cannot be honoured.
    std::vector<uint8_t> bad = kCalChunkBytes;
    bad[4] = 59;
    assert_int_equal(int(parse_cal_chunk(bad.data(), 64, cp)), int(Reject::BadValue));
}

void test_crc32(void **) {
    // The standard check value of CRC-32/ISO-HDLC.
    assert_int_equal(crc32(reinterpret_cast<const uint8_t *>("123456789"), 9), 0xCBF43926u);
    assert_int_equal(crc32(nullptr, 0), 0u);
    // Incremental use gives the same as one pass.
    const uint8_t *s = reinterpret_cast<const uint8_t *>("123456789");
    assert_int_equal(crc32(s + 4, 5, crc32(s, 4)), 0xCBF43926u);
}

// Random field values survive serialize -> parse unchanged.
void test_input_round_trip(void **) {
    uint64_t x = 88172645463325252ull;
    auto rnd = [&] {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        return x;
    };
    for (int k = 0; k < 2000; ++k) {
        InputReport r;
        r.status = uint16_t(rnd());
        r.sequence = uint32_t(rnd());
        r.device_time_us = rnd();
        for (auto &p : r.pot_adc) p = uint16_t(rnd());
        // A random unit quaternion, quantised.
        double q[4], n = 0;
        for (double &c : q) {
            c = double(int64_t(rnd() % 20001) - 10000);
            n += c * c;
        }
        if (n == 0) continue;
        for (int i = 0; i < 4; ++i) r.quat_q14[i] = int16_t(std::lround(q[i] / std::sqrt(n) * kQ14));
        r.hall_adc = uint16_t(rnd());
        r.buttons = uint16_t(rnd());
        uint8_t b[kInputReportSize];
        serialize_input(r, b);
        InputReport p;
        assert_int_equal(int(parse_input(b, sizeof b, p)), int(Reject::None));
        assert_int_equal(p.status, r.status);
        assert_int_equal(p.sequence, r.sequence);
        assert_true(p.device_time_us == r.device_time_us);
        for (int i = 0; i < 4; ++i) {
            assert_int_equal(p.pot_adc[i], r.pot_adc[i]);
            assert_int_equal(p.quat_q14[i], r.quat_q14[i]);
        }
        assert_int_equal(p.hall_adc, r.hall_adc);
        assert_int_equal(p.buttons, r.buttons);
    }
}

void test_rejections(void **) {
    InputReport r;
    std::vector<uint8_t> b = kInputBytes;
    // Short: every length below 64.
    for (size_t n = 0; n < kInputReportSize; ++n)
        assert_int_equal(int(parse_input(b.data(), n, r)), int(Reject::Short));
    assert_int_equal(int(parse_input(nullptr, 64, r)), int(Reject::Short));
    // A longer report (newer firmware) is accepted; extra bytes ignored.
    std::vector<uint8_t> longer = b;
    longer.resize(80, 0xAA);
    assert_int_equal(int(parse_input(longer.data(), longer.size(), r)), int(Reject::None));
    // Wrong report ID.
    b = kInputBytes;
    b[0] = 0x02;
    assert_int_equal(int(parse_input(b.data(), b.size(), r)), int(Reject::WrongReportId));
    // Wrong protocol version.
    b = kInputBytes;
    b[1] = 2;
    assert_int_equal(int(parse_input(b.data(), b.size(), r)), int(Reject::WrongVersion));
    // All-zero quaternion.
    b = kInputBytes;
    std::memset(b.data() + 24, 0, 8);
    assert_int_equal(int(parse_input(b.data(), b.size(), r)), int(Reject::QuatZero));
    // Norm far from one: a byte-swapped w (0x0020 -> 32 instead of 8192).
    b = kInputBytes;
    std::swap(b[24], b[25]);
    assert_int_equal(int(parse_input(b.data(), b.size(), r)), int(Reject::QuatNorm));
    // The threshold, 0.01, on either side: w = 16384 * (1 +- 0.009) passes,
    // 16384 * (1 +- 0.011) fails.
    for (double f : {0.991, 1.009, 0.989, 1.011}) {
        b = kInputBytes;
        std::memset(b.data() + 24, 0, 8);
        put_u16(b.data() + 24, uint16_t(int16_t(std::lround(16384 * f))));
        const bool inside = std::fabs(f - 1) < kQuatNormTolerance;
        assert_int_equal(int(parse_input(b.data(), b.size(), r)), int(inside ? Reject::None : Reject::QuatNorm));
    }
    // A reserved byte set is no error (forward compatible), only noted.
    b = kInputBytes;
    b[63] = 1;
    assert_int_equal(int(parse_input(b.data(), b.size(), r)), int(Reject::None));
    assert_true(r.reserved_nonzero);
    // Every reason has its own text.
    const Reject all[] = {Reject::Short, Reject::WrongReportId, Reject::WrongVersion, Reject::QuatZero,
                          Reject::QuatNorm, Reject::BadValue};
    for (size_t i = 0; i < 6; ++i)
        for (size_t j = i + 1; j < 6; ++j) assert_string_not_equal(reject_text(all[i]), reject_text(all[j]));
}

void test_info_rejections(void **) {
    DeviceInfoReport r;
    std::string d;
    std::vector<uint8_t> b = kInfoBytes;
    assert_int_equal(int(parse_device_info(b.data(), 127, r, &d)), int(Reject::Short));
    b[0] = 0x01;
    assert_int_equal(int(parse_device_info(b.data(), b.size(), r, &d)), int(Reject::WrongReportId));
    b = kInfoBytes;
    b[1] = 9;
    assert_int_equal(int(parse_device_info(b.data(), b.size(), r, &d)), int(Reject::WrongVersion));
    struct Case {
        size_t off;
        std::vector<uint8_t> bytes;
        const char *field;
    } cases[] = {
        {6, {0}, "adc_bits"},
        {28, {0, 0, 0, 0}, "pot_scale_mm[0]"},
        {40, {0, 0, 0x80, 0xFF}, "pot_scale_mm[3]"}, // -inf
        {48, {0, 0, 0xC0, 0x7F}, "pot_offset_mm[1]"}, // NaN
        {68, {0, 0, 0x80, 0x43}, "geometry"},         // m = 256 >= 2b
        {74, {0x28, 0x0A}, "hall_closed equals hall_open"},
        {76, {0, 0, 0, 0}, "grip_open_rad"},
        {10, {0x07}, "serial"},
        {24, {0, 0, 0, 0}, "report_rate_hz"},
    };
    for (const Case &c : cases) {
        b = kInfoBytes;
        std::memcpy(b.data() + c.off, c.bytes.data(), c.bytes.size());
        d.clear();
        assert_int_equal(int(parse_device_info(b.data(), b.size(), r, &d)), int(Reject::BadValue));
        assert_non_null(std::strstr(d.c_str(), c.field));
    }
}

void test_descriptor(void **) {
    // The report sizes the descriptor declares are the ones the parser
    // expects: Report Count (0x95) after each Report ID (0x85), 8-bit items.
    int id = -1;
    std::vector<std::pair<int, int>> seen;
    for (size_t i = 0; i + 1 < kReportDescriptorSize; ++i) {
        if (kReportDescriptor[i] == 0x85) id = kReportDescriptor[++i];
        else if (kReportDescriptor[i] == 0x95 && id >= 0) seen.emplace_back(id, kReportDescriptor[++i] + 1);
        else if (kReportDescriptor[i] == 0x06 || kReportDescriptor[i] == 0x26) i += 2;
        else if ((kReportDescriptor[i] & 0x03) == 1) ++i;
    }
    assert_int_equal(seen.size(), 4);
    assert_int_equal(seen[0].first, 1);
    assert_int_equal(seen[0].second, int(kInputReportSize));
    assert_int_equal(seen[1].second, int(kDeviceInfoReportSize));
    assert_int_equal(seen[2].second, int(kCalHeaderReportSize));
    assert_int_equal(seen[3].second, int(kCalChunkReportSize));
    assert_int_equal(kReportDescriptor[kReportDescriptorSize - 1], 0xC0);
    assert_int_equal(kReportDescriptorSize, 47); // as docs/protocol.md lists it
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_input_golden),  cmocka_unit_test(test_info_golden),
        cmocka_unit_test(test_cal_golden),    cmocka_unit_test(test_crc32),
        cmocka_unit_test(test_input_round_trip), cmocka_unit_test(test_rejections),
        cmocka_unit_test(test_info_rejections), cmocka_unit_test(test_descriptor),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
