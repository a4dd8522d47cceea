// Deterministic mutation test (runs under gcc in ctest, where libFuzzer is
// not available): every golden vector, truncated at every length, every
// single bit flipped, every byte set to 0x00/0xFF, plus 20000 seeded random
// multi-byte mutations, through every parser. Nothing may crash (the
// sanitizer builds catch what a plain build would not), and the round-trip
// invariants of fuzz_body.cpp must hold.
#include <cstdint>
#include <string>
#include <vector>

#include "../unit/device/test_util.h"
#include "device/protocol.h"
#include "fuzz_body.h"

// cmocka last: its fail() macro must not meet the C++ headers.
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
extern "C" {
#include <cmocka.h>
}

namespace {

std::vector<std::vector<uint8_t>> seeds() {
    std::vector<std::vector<uint8_t>> s;
    for (const char *f : {"input_report.hex", "device_info.hex", "cal_header.hex", "cal_chunk.hex"}) {
        std::vector<uint8_t> b;
        if (!cdm_test::read_hex(std::string(CDM_TEST_DATA_DIR "/protocol/") + f, b)) fail_msg("cannot read %s", f);
        s.push_back(b);
    }
    // A small replay file: header, the device-info report, two records.
    std::vector<uint8_t> rep = {'C', 'D', 'M', 'R', 'P', 'L', 'A', 'Y', 1, 0, 128, 0};
    rep.insert(rep.end(), s[1].begin(), s[1].end());
    for (int k = 0; k < 2; ++k) {
        uint8_t h[10] = {};
        cdm::proto::put_u64(h, 1000000ull * (k + 1));
        cdm::proto::put_u16(h + 8, 64);
        rep.insert(rep.end(), h, h + 10);
        rep.insert(rep.end(), s[0].begin(), s[0].end());
    }
    s.push_back(rep);
    return s;
}

void check(const std::vector<uint8_t> &b, const char *what, size_t where) {
    const int rc = cdm_fuzz::check_bytes(b.data(), b.size());
    if (rc != 0) fail_msg("invariant %d broken (%s at %zu)", rc, what, where);
}

void test_systematic(void **) {
    for (const auto &seed : seeds()) {
        check(seed, "seed", 0);
        for (size_t n = 0; n < seed.size(); ++n) check(std::vector<uint8_t>(seed.begin(), seed.begin() + n), "cut", n);
        for (size_t i = 0; i < seed.size(); ++i) {
            for (int bit = 0; bit < 8; ++bit) {
                auto b = seed;
                b[i] ^= uint8_t(1u << bit);
                check(b, "bit flip", i * 8 + bit);
            }
            for (uint8_t v : {uint8_t(0x00), uint8_t(0xFF)}) {
                auto b = seed;
                b[i] = v;
                check(b, "byte set", i);
            }
        }
    }
}

void test_random(void **) {
    uint64_t x = 0x2545F4914F6CDD1Dull; // fixed seed: the same cases every run
    auto rnd = [&] {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        return x;
    };
    const auto s = seeds();
    for (int k = 0; k < 20000; ++k) {
        auto b = s[rnd() % s.size()];
        const int edits = 1 + int(rnd() % 8);
        for (int e = 0; e < edits; ++e) {
            switch (rnd() % 4) {
            case 0: b[rnd() % b.size()] = uint8_t(rnd()); break;
            case 1: b.resize(rnd() % (b.size() + 1)); break;
            case 2: b.push_back(uint8_t(rnd())); break;
            default: b.insert(b.begin() + long(rnd() % (b.size() + 1)), uint8_t(rnd())); break;
            }
            if (b.empty()) b.push_back(0x01);
        }
        check(b, "random", size_t(k));
    }
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {cmocka_unit_test(test_systematic), cmocka_unit_test(test_random)};
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
