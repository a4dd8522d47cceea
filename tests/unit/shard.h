// Runs one shard of a CMocka group: `program K/N` runs the tests whose index
// in the group is K-1 modulo N (K from 1 to N); no argument runs them all.
// ctest registers a long program as N tests (cdm_add_cmocka_test ... SHARDS
// N), so that the sanitizer builds, where calib_diagnose costs 20-26 times the
// plain build's, spread it over the cores instead of waiting on it.
#pragma once

#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
extern "C" {
#include <cmocka.h>
}

#include <cstdio>
#include <cstdlib>
#include <vector>

namespace cdm_test {

template <size_t Count>
int run_shard(int argc, char** argv, const char* group, const CMUnitTest (&tests)[Count]) {
    if (argc < 2) return _cmocka_run_group_tests(group, tests, Count, nullptr, nullptr);
    unsigned k = 0, n = 0;
    char tail = 0;
    if (argc > 2 || std::sscanf(argv[1], "%u/%u%c", &k, &n, &tail) != 2 || n == 0 || k == 0 || k > n) {
        std::fprintf(stderr, "%s: expected no argument or a shard K/N with 1 <= K <= N, got '%s'\n", argv[0],
                     argv[1]);
        return 2;
    }
    std::vector<CMUnitTest> part;
    for (size_t i = k - 1; i < Count; i += n) part.push_back(tests[i]);
    return _cmocka_run_group_tests(group, part.data(), part.size(), nullptr, nullptr);
}

} // namespace cdm_test
