// parse_decimal's contract: a whole field or nothing, correctly rounded.
// The references are independent of std::from_chars: the compiler's own
// rounding of the same literals, and the round trip of printf's %.17g
// (17 significant digits identify a double, so a correctly rounded reader
// gives back the very bits printed).
#include <setjmp.h>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>

#include "io/decimal.h"

extern "C" {
#include <cmocka.h>
}

namespace {

void reads(const char *s, double want) {
    double got = 0;
    if (!cdm::io::parse_decimal(s, s + std::strlen(s), got)) fail_msg("'%s' refused", s);
    if (std::memcmp(&want, &got, sizeof want) != 0) fail_msg("'%s': %.17g, expected %.17g", s, got, want);
}

void refuses(const std::string &s) {
    double got = 0;
    if (cdm::io::parse_decimal(s.data(), s.data() + s.size(), got)) fail_msg("'%s' read as %.17g", s.c_str(), got);
}

// The jig files' form, the halfway cases of binary rounding, 15 to 17
// digits, the range's ends: each against the compiler's literal.
void test_decimal_reads_exact_values(void **) {
    reads("0", 0.0);
    reads("-0.0000", -0.0);
    reads("211.0500", 211.05);
    reads("-60.0000", -60.0);
    reads("007.50", 7.5);
    reads("0.1", 0.1);
    reads("0.3", 0.3);
    reads("4.35", 4.35);
    reads("2.675", 2.675);
    reads("123456789012345", 123456789012345.0);
    reads("9007199254740993", 9007199254740993.0); // 2^53 + 1: rounds to even
    reads("0.0000000000000000000001", 1e-22);
    reads("1.000000000000000000001", 1.000000000000000000001);
    reads("5e-324", 5e-324);
    reads("1e308", 1e308);
    reads("1E-5", 1e-5);
    reads("5.", 5.0);
    reads(".5", 0.5);
    reads("-.5", -0.5);
    const std::string minus_zero = "-0";
    double v = 1;
    assert_true(cdm::io::parse_decimal(minus_zero.data(), minus_zero.data() + minus_zero.size(), v));
    assert_true(std::signbit(v));
}

// A field is read whole or refused: no sign but '-', no space, no trailing
// byte, no hexadecimal, nothing past a double's range.
void test_decimal_refuses_partial_fields(void **) {
    for (const char *s : {"", "-", ".", "+5", " 1", "1 ", "1.2.3", "1,5", "0x10", "--1", "12a", "1e309", "-1e309",
                          "1e-400"})
        refuses(s);
}

// 200,000 doubles over the whole range, printed with 17 significant
// digits and in the jig files' fixed four decimals: each read back as the
// bits printf's correctly rounded output identifies.
void test_decimal_round_trips_printf(void **) {
    std::mt19937_64 rng(20261127);
    char buf[64];
    for (int i = 0; i < 200000; ++i) {
        uint64_t bits = rng();
        double d;
        std::memcpy(&d, &bits, sizeof d);
        if (!std::isfinite(d)) continue;
        std::snprintf(buf, sizeof buf, "%.17g", d);
        reads(buf, d);
        const double mm = std::ldexp(double(rng() >> 11), -53) * 600.0 - 300.0;
        std::snprintf(buf, sizeof buf, "%.4f", mm);
        double want = 0;
        std::sscanf(buf, "%lf", &want); // glibc's strtod: correctly rounded
        reads(buf, want);
    }
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_decimal_reads_exact_values),
        cmocka_unit_test(test_decimal_refuses_partial_fields),
        cmocka_unit_test(test_decimal_round_trips_printf),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
