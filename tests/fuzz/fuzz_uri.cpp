// Device URIs: parse_uri, then every option through the typed option
// readers the transports use; a refusal always says why.
#include <cstdlib>
#include <string>

#include "device/transport.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    cdm::Uri u;
    std::string err;
    if (cdm::parse_uri(text, u, err) != 0) {
        if (err.empty()) std::abort();
        return 0;
    }
    for (const auto &kv : u.options) {
        double d = 0;
        uint64_t n = 0;
        std::string e1, e2;
        if (!cdm::option_double(u, kv.first, kv.second, -1e9, 1e9, d, e1) && e1.empty()) std::abort();
        if (!cdm::option_u64(u, kv.first, kv.second, 0, 1000000, n, e2) && e2.empty()) std::abort();
    }
    return 0;
}
