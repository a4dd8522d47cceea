// Small helpers shared by the device tests.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

namespace cdm_test {

// Polls `pred` every millisecond until it holds or `timeout_ms` passes.
template <class P>
bool wait_until(P pred, int timeout_ms) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < end) {
        if (pred()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return pred();
}

// Hex files: bytes as two hex digits separated by white space; '#' starts a
// comment. Returns false if the file is missing or malformed.
inline bool read_hex(const std::string &path, std::vector<uint8_t> &out) {
    std::FILE *f = std::fopen(path.c_str(), "r");
    if (!f) return false;
    out.clear();
    int c;
    int nibble = -1;
    bool ok = true;
    while ((c = std::fgetc(f)) != EOF) {
        if (c == '#') {
            while ((c = std::fgetc(f)) != EOF && c != '\n') {}
            continue;
        }
        if (c == ' ' || c == '\n' || c == '\t' || c == '\r') {
            if (nibble >= 0) ok = false; // odd digit count
            continue;
        }
        int v;
        if (c >= '0' && c <= '9') v = c - '0';
        else if (c >= 'a' && c <= 'f') v = c - 'a' + 10;
        else if (c >= 'A' && c <= 'F') v = c - 'A' + 10;
        else { ok = false; break; }
        if (nibble < 0) nibble = v;
        else {
            out.push_back(uint8_t(nibble << 4 | v));
            nibble = -1;
        }
    }
    std::fclose(f);
    return ok && nibble < 0;
}

inline bool write_hex(const std::string &path, const std::string &comment, const std::vector<uint8_t> &b) {
    std::FILE *f = std::fopen(path.c_str(), "w");
    if (!f) return false;
    std::fprintf(f, "# %s\n# %zu bytes, 16 per line; docs/protocol.md gives the layout.\n", comment.c_str(), b.size());
    for (size_t i = 0; i < b.size(); ++i) std::fprintf(f, "%02x%s", b[i], (i % 16 == 15 || i + 1 == b.size()) ? "\n" : " ");
    return std::fclose(f) == 0;
}

} // namespace cdm_test
