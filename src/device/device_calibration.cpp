// The device's calibration store (feature reports 0x03/0x04, docs/protocol.md
// "Sequences"): cdm_device_calibration_read/write, one transfer at a time.
#include <algorithm>
#include <cstring>
#include <vector>

#include "device/device.h"

using namespace cdm;

// ------------------------------------------------------------ calibration I/O

namespace {
int feature_get(Transport &t, uint8_t id, uint8_t *buf, size_t len, std::string &err) {
    std::memset(buf, 0, len);
    buf[0] = id;
    const int n = t.get_feature(buf, len, err);
    if (n >= 0 && size_t(n) < len) {
        err = "feature report 0x0" + std::to_string(id) + ": device returned " + std::to_string(n) + " of " +
              std::to_string(len) + " bytes";
        return CDM_ERR_PROTOCOL;
    }
    return n < 0 ? n : CDM_OK;
}
} // namespace

int cdm_device::calibration_read(char *out, size_t cap, size_t *len) {
    using namespace cdm::proto;
    std::lock_guard<std::mutex> lock(cal_mu_);
    std::string err;
    uint8_t buf[kCalChunkReportSize];
    auto fail_with = [&](int code, const std::string &text) {
        set_error("reading the stored calibration: " + text);
        return code;
    };
    int rc = feature_get(*transport_, kCalHeaderReportId, buf, kCalHeaderReportSize, err);
    if (rc != CDM_OK) return fail_with(rc, err);
    CalHeader h;
    if (parse_cal_header(buf, kCalHeaderReportSize, h) != Reject::None)
        return fail_with(CDM_ERR_PROTOCOL, "malformed calibration header (feature report 0x03)");
    *len = 0;
    if (h.state == CalState::Empty) return fail_with(CDM_ERR_NO_DATA, "the device stores no calibration");
    if (h.state == CalState::Writing)
        return fail_with(CDM_ERR_NO_DATA, "a calibration write is in progress or was interrupted");
    if (h.state == CalState::CommitFailed)
        return fail_with(CDM_ERR_CRC, "the last calibration write failed the device's CRC check");
    if (h.length > kCalMaxLength)
        return fail_with(CDM_ERR_PROTOCOL, "device claims " + std::to_string(h.length) + " bytes (max 16384)");
    *len = h.length;
    if (h.length > cap)
        return fail_with(CDM_ERR_NO_MEM, "buffer of " + std::to_string(cap) + " bytes, " +
                                             std::to_string(h.length) + " needed");
    CalChunk seek;
    seek.op = CalChunkOp::SeekRead;
    seek.offset = 0;
    serialize_cal_chunk(seek, buf);
    rc = transport_->send_feature(buf, kCalChunkReportSize, err);
    if (rc != CDM_OK) return fail_with(rc, err);
    std::vector<uint8_t> data;
    data.reserve(h.length);
    while (data.size() < h.length) {
        rc = feature_get(*transport_, kCalChunkReportId, buf, kCalChunkReportSize, err);
        if (rc != CDM_OK) return fail_with(rc, err);
        CalChunk c;
        if (parse_cal_chunk(buf, kCalChunkReportSize, c) != Reject::None || c.offset != data.size() ||
            c.length == 0 || data.size() + c.length > h.length)
            return fail_with(CDM_ERR_PROTOCOL, "unexpected calibration chunk at offset " + std::to_string(data.size()));
        data.insert(data.end(), c.data.begin(), c.data.begin() + c.length);
    }
    if (h.length) std::memcpy(out, data.data(), h.length);
    if (crc32(data.data(), data.size()) != h.crc32)
        return fail_with(CDM_ERR_CRC, "stored calibration (" + std::to_string(h.length) +
                                          " bytes) does not match its CRC-32");
    return CDM_OK;
}

int cdm_device::calibration_write(const char *data, size_t len) {
    using namespace cdm::proto;
    std::lock_guard<std::mutex> lock(cal_mu_);
    std::string err;
    auto fail_with = [&](int code, const std::string &text) {
        set_error("writing the calibration: " + text);
        return code;
    };
    if (len > kCalMaxLength)
        return fail_with(CDM_ERR_INVALID_ARG,
                         std::to_string(len) + " bytes do not fit the device's 16384-byte store");
    const uint8_t *bytes = reinterpret_cast<const uint8_t *>(data);
    uint8_t buf[kCalChunkReportSize];
    CalHeader h;
    h.op = CalHeaderOp::BeginWrite;
    h.length = uint32_t(len);
    h.crc32 = crc32(bytes, len);
    serialize_cal_header(h, buf);
    int rc = transport_->send_feature(buf, kCalHeaderReportSize, err);
    if (rc != CDM_OK) return fail_with(rc, err);
    for (size_t off = 0; off < len; off += kCalChunkMaxData) {
        CalChunk c;
        c.op = CalChunkOp::WriteData;
        c.offset = uint16_t(off);
        c.length = uint8_t(std::min(kCalChunkMaxData, len - off));
        std::memcpy(c.data.data(), bytes + off, c.length);
        serialize_cal_chunk(c, buf);
        rc = transport_->send_feature(buf, kCalChunkReportSize, err);
        if (rc != CDM_OK) return fail_with(rc, "chunk at offset " + std::to_string(off) + ": " + err);
    }
    CalHeader commit;
    commit.op = CalHeaderOp::Commit;
    commit.length = uint32_t(len);
    commit.crc32 = h.crc32;
    serialize_cal_header(commit, buf);
    rc = transport_->send_feature(buf, kCalHeaderReportSize, err);
    if (rc != CDM_OK) return fail_with(rc, "commit: " + err);
    rc = feature_get(*transport_, kCalHeaderReportId, buf, kCalHeaderReportSize, err);
    if (rc != CDM_OK) return fail_with(rc, err);
    CalHeader after;
    if (parse_cal_header(buf, kCalHeaderReportSize, after) != Reject::None)
        return fail_with(CDM_ERR_PROTOCOL, "malformed calibration header after commit");
    if (after.state != CalState::Valid || after.length != len || after.crc32 != h.crc32)
        return fail_with(CDM_ERR_CRC, "the device did not accept the data (state " +
                                          std::to_string(int(after.state)) + ", CRC check failed)");
    return CDM_OK;
}
