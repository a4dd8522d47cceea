#include "io/decimal.h"

#include <charconv>
#include <cstdint>
#include <system_error>

namespace cdm::io {

namespace {
// At most 15 digits: an integer below 10^15 < 2^53, over a power of ten
// up to 10^15; both exact doubles.
constexpr int kMaxDigits = 15;
constexpr double kPow10[kMaxDigits + 1] = {1e0, 1e1, 1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                           1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15};
} // namespace

bool parse_decimal(const char *b, const char *e, double &v) {
    const char *p = b;
    const bool neg = p < e && *p == '-';
    if (neg) ++p;
    std::uint64_t m = 0;
    int digits = 0, frac = 0;
    const char *const d0 = p;
    for (; p < e && static_cast<unsigned>(*p - '0') < 10 && digits <= kMaxDigits; ++p, ++digits)
        m = 10 * m + static_cast<unsigned>(*p - '0');
    bool fast = p != d0;
    if (fast && p < e && *p == '.') {
        const char *const f0 = ++p;
        for (; p < e && static_cast<unsigned>(*p - '0') < 10 && digits <= kMaxDigits; ++p, ++digits, ++frac)
            m = 10 * m + static_cast<unsigned>(*p - '0');
        fast = p != f0; // "5." goes to from_chars
    }
    if (fast && p == e && digits <= kMaxDigits) { // (so frac <= 15)
        const double x = frac ? static_cast<double>(m) / kPow10[frac] : static_cast<double>(m);
        v = neg ? -x : x;
        return true;
    }
    const auto r = std::from_chars(b, e, v);
    return r.ec == std::errc() && r.ptr == e && b != e;
}

} // namespace cdm::io
