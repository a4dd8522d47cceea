#include "fuzz_body.h"

#include <cstring>
#include <string>
#include <vector>

#include "cdm/cdm.h"
#include "device/protocol.h"
#include "device/recording/replay_format.h"

namespace cdm_fuzz {

using namespace cdm::proto;

int check_bytes(const uint8_t *data, size_t size) {
    // Input report: accepted bytes re-serialise to themselves (reserved
    // bytes aside, which the serializer writes as zero).
    InputReport r;
    if (parse_input(data, size, r) == Reject::None) {
        uint8_t out[kInputReportSize];
        serialize_input(r, out);
        if (std::memcmp(out, data, 36) != 0) return 1;
        InputReport again;
        if (parse_input(out, sizeof out, again) != Reject::None) return 2;
        if (again.sequence != r.sequence || again.pot_adc != r.pot_adc || again.quat_q14 != r.quat_q14) return 3;
    }
    DeviceInfoReport info;
    std::string detail;
    if (parse_device_info(data, size, info, &detail) == Reject::None) {
        uint8_t out[kDeviceInfoReportSize];
        serialize_device_info(info, out);
        // Bytes 0..79 carry every field; float fields compare bitwise.
        if (std::memcmp(out, data, 7) != 0 || std::memcmp(out + 8, data + 8, 72) != 0) return 4;
    }
    CalHeader h;
    if (parse_cal_header(data, size, h) == Reject::None) {
        uint8_t out[kCalHeaderReportSize];
        serialize_cal_header(h, out);
        if (std::memcmp(out, data, 3) != 0 || std::memcmp(out + 4, data + 4, 16) != 0) return 5;
    }
    CalChunk c;
    if (parse_cal_chunk(data, size, c) == Reject::None) {
        if (c.length > kCalChunkMaxData) return 6;
        uint8_t out[kCalChunkReportSize];
        serialize_cal_chunk(c, out);
        if (std::memcmp(out, data, 5) != 0 || std::memcmp(out + 6, data + 6, c.length) != 0) return 7;
    }
    // Replay framing: never reads out of bounds; every record it accepts
    // lies inside the file.
    cdm::replay::File f;
    std::string err;
    const int rc = cdm::replay::parse(std::vector<uint8_t>(data, data + size), "fuzz", f, err);
    if (rc == CDM_OK) {
        for (const auto &rec : f.records)
            if (rec.offset + rec.length > size || rec.length == 0) return 8;
    } else if (rc != CDM_ERR_PARSE || err.find("byte") == std::string::npos) {
        return 9;
    }
    return 0;
}

} // namespace cdm_fuzz
