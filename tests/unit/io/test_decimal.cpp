// parse_decimal against std::from_chars, the definition it must match bit
// for bit: accepted or refused alike, and the same double when accepted.
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <charconv>
#include <cstring>
#include <random>
#include <string>
#include <system_error>

#include "io/decimal.h"

extern "C" {
#include <cmocka.h>
}

namespace {

struct Seen {
    long compared = 0, accepted = 0, fast_shape = 0;
};

// One field through both readers; fails the test on any disagreement.
void same(const std::string &s, Seen &seen) {
    double want = 0, got = 0;
    const char *b = s.data(), *e = s.data() + s.size();
    const auto r = std::from_chars(b, e, want);
    const bool want_ok = r.ec == std::errc() && r.ptr == e && b != e;
    const bool got_ok = cdm::io::parse_decimal(b, e, got);
    if (want_ok != got_ok) fail_msg("'%s': from_chars %s it, parse_decimal %s it", s.c_str(),
                                    want_ok ? "reads" : "refuses", got_ok ? "reads" : "refuses");
    if (want_ok && std::memcmp(&want, &got, sizeof want) != 0)
        fail_msg("'%s': from_chars %.17g, parse_decimal %.17g", s.c_str(), want, got);
    ++seen.compared;
    seen.accepted += want_ok;
}

// Fields of the fast path's shape and just past it, and others.
void test_decimal_matches_from_chars(void **) {
    Seen seen;
    for (const char *s : {"0", "-0", "0.0", "-0.0000", "211.0500", "-60.0000", "30", "007.50", "0.1", "0.3",
                          "123456789012345", "-123456789012345", "12345678901234.5", "1234567890123456",
                          "9007199254740993", "0.0000000000000000000001", "1.000000000000000000001",
                          "4.35", "2.675", "5e-324", "1e308", "1e309", "", "-", ".", "5.", ".5", "-.5", "+5",
                          "1.2.3", "1,5", " 1", "1 ", "inf", "nan", "-inf", "0x10", "1e5", "1E-5", "--1", "12a"})
        same(s, seen);
    // Random numerals around the fast path's limits (15 digits, 22 after
    // the point): the digits before and after the point 0-20 and 0-25, a
    // sign, sometimes an exponent or a stray character.
    std::mt19937_64 rng(20261127);
    auto pick = [&](int n) { return int(rng() % uint64_t(n)); };
    for (int i = 0; i < 200000; ++i) {
        std::string s;
        if (pick(3) == 0) s += '-';
        const int lead = pick(21), frac = pick(4) == 0 ? 0 : pick(26);
        for (int k = 0; k < lead; ++k) s += char('0' + pick(10));
        if (frac > 0 || pick(8) == 0) s += '.';
        for (int k = 0; k < frac; ++k) s += char('0' + pick(10));
        switch (pick(40)) {
        case 0: s += "e" + std::to_string(pick(40) - 20); break;
        case 1: s += 'x'; break;
        case 2: s.insert(0, " "); break;
        default: break;
        }
        seen.fast_shape += lead + frac > 0 && lead + frac <= 15 && s.find_first_of("ex ") == std::string::npos;
        same(s, seen);
    }
    // The comparison covered both readers' sides.
    assert_true(seen.accepted > seen.compared / 2);
    assert_true(seen.fast_shape > seen.compared / 4);
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_decimal_matches_from_chars),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
