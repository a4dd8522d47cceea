// MCAP recordings (src/io/mcap.*, src/device/recording/recording_mcap.*): any bytes
// are either refused with "NAME: byte OFFSET: what" or accepted with every
// message and record inside the file, lengths within the format's bounds.
#include <cstdlib>
#include <string>
#include <vector>

#include "cdm/cdm.h"
#include "device/recording/replay_format.h"
#include "io/mcap.h"

namespace {
bool names_a_byte(const std::string &err) { return err.rfind("fuzz.mcap: byte ", 0) == 0; }
} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    std::string err;
    cdm::mcap::File f;
    if (!cdm::mcap::parse(data, size, "fuzz.mcap", f, err)) {
        if (!names_a_byte(err)) std::abort();
    } else {
        for (const auto &m : f.messages)
            if (m.offset < sizeof cdm::mcap::kMagic || m.offset > size || m.length > size - m.offset ||
                !f.channels.count(m.channel))
                std::abort();
        for (const auto &c : f.channels)
            if (c.second.schema_id != 0 && !f.schemas.count(c.second.schema_id)) std::abort();
        if (f.complete && f.truncated_bytes != 0) std::abort();
    }
    // The cdm layout on top, exactly as replay: opens it.
    cdm::replay::File r;
    std::string rerr;
    if (cdm::replay::parse(std::vector<uint8_t>(data, data + size), "fuzz.mcap", r, rerr) != CDM_OK) {
        if (!names_a_byte(rerr)) std::abort();
        return 0;
    }
    if (r.info.empty() || r.info.size() > cdm::replay::kMaxReport) std::abort();
    uint64_t last = 0;
    for (const auto &rec : r.records) {
        if (rec.length == 0 || rec.length > cdm::replay::kMaxReport || rec.offset > r.bytes.size() ||
            rec.length > r.bytes.size() - rec.offset || rec.host_ns < last)
            std::abort();
        last = rec.host_ns;
    }
    return 0;
}
