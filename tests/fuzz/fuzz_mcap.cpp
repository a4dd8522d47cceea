// MCAP recordings (src/io/mcap.*, src/device/recording/recording_mcap.*): any bytes
// are either refused with "NAME: byte OFFSET: what" or accepted with every
// message inside the file or inside one decompressed chunk (zstd, lz4; the
// corpus has both), lengths within the format's bounds and decompressed
// bytes within the reader's cap.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "cdm/cdm.h"
#include "device/recording/replay_format.h"
#include "io/mcap.h"

namespace {
bool names_a_byte(const std::string &err) { return err.rfind("fuzz.mcap: byte ", 0) == 0; }
// [p, p + n) inside [base, base + size), compared as addresses.
bool inside(const uint8_t *p, size_t n, const uint8_t *base, size_t size) {
    const auto a = reinterpret_cast<uintptr_t>(p), b = reinterpret_cast<uintptr_t>(base);
    return a >= b && a - b <= size && n <= size - (a - b);
}
} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    std::string err;
    cdm::mcap::File f;
    if (!cdm::mcap::parse(data, size, "fuzz.mcap", f, err)) {
        if (!names_a_byte(err)) std::abort();
    } else {
        // Each message lies inside the file or inside one decompressed chunk
        // (compressed chunks: zstd, lz4), and names a byte of the file.
        for (const auto &m : f.messages) {
            bool ok = inside(m.data, m.length, data, size);
            for (const auto &c : f.chunk_data) ok = ok || inside(m.data, m.length, c.bytes.get(), c.size);
            if (!ok) std::abort();
            if (m.offset < sizeof cdm::mcap::kMagic || m.offset > size || !f.channels.count(m.channel)) std::abort();
        }
        for (const auto &c : f.channels)
            if (c.second.schema_id != 0 && !f.schemas.count(c.second.schema_id)) std::abort();
        if (f.complete && f.truncated_bytes != 0) std::abort();
        uint64_t unpacked = 0;
        for (const auto &c : f.chunk_data) unpacked += c.size;
        if (unpacked > cdm::mcap::kMaxUncompressedBytes) std::abort();
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
