// Deterministic mutations of valid inputs through the calibration-side
// parsers (the libFuzzer target's body, without clang): truncations at every
// byte, byte flips, and seeded random edits of a dataset, a device
// description and a calibration. The check is fuzz_calib_one's: no crash, no
// silent refusal, no non-finite output.
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <random>
#include <setjmp.h>
#include <string>
#include <vector>

#include "fuzz_calib_body.h"

extern "C" {
#include <cmocka.h>
}

static const char *kSeeds[] = {
    "point,x_ref,y_ref,z_ref,l1,l2,l3,l4,extra\n"
    "0,30,-60,-60,211.07,277.48,110.23,211.14,1\n"
    "0,30,-60,-60,211.02,277.50,110.18,211.01,1\n"
    "1,40,0,5,190.1,191.2,189.9,190.7,2\n",
    "{\"a_mm\": 150.0, \"b_mm\": 150.0, \"m_mm\": 30.0, \"exit_axis\": [[1,0,0],[1,0,0],[1,0,0],[1,0,0]]}",
    "{\"format\":\"cdm-calibration\",\"version\":1,\"device\":{\"a_mm\":150,\"b_mm\":150,\"m_mm\":30},"
    "\"effects\":[{\"name\":\"exit_pulley\",\"params\":{\"radius_mm\":5}},"
    "{\"name\":\"cable_offset\",\"params\":{\"o1\":0.1,\"o2\":-0.2,\"o3\":0.3,\"o4\":0}}]}",
};

static void run(const std::string &s) { fuzz_calib_one(reinterpret_cast<const uint8_t *>(s.data()), s.size()); }

static void truncations_and_flips(void **) {
    for (const char *seed : kSeeds) {
        const std::string s(seed);
        for (size_t n = 0; n <= s.size(); ++n) run(s.substr(0, n));
        for (size_t i = 0; i < s.size(); ++i)
            for (char c : {'\0', ',', '\n', '-', 'e', '9', '"', '}', 'x'}) {
                std::string t = s;
                t[i] = c;
                run(t);
            }
    }
}

static void random_edits(void **) {
    std::mt19937_64 rng(20261122);
    for (int k = 0; k < 3000; ++k) {
        std::string s(kSeeds[size_t(k) % 3]);
        const int edits = 1 + int(rng() % 6);
        for (int e = 0; e < edits && !s.empty(); ++e) {
            const size_t i = rng() % s.size();
            switch (rng() % 4) {
            case 0: s[i] = char(rng() % 256); break;
            case 1: s.erase(i, 1 + rng() % 8); break;
            case 2: s.insert(i, std::string(1 + rng() % 4, char(rng() % 256))); break;
            default: s.insert(i, s.substr(rng() % s.size(), 1 + rng() % 16)); break;
            }
        }
        run(s);
    }
}

int main(void) {
    const struct CMUnitTest tests[] = {cmocka_unit_test(truncations_and_flips), cmocka_unit_test(random_edits)};
    return cmocka_run_group_tests(tests, NULL, NULL);
}
