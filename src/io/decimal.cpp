#include "io/decimal.h"

#include <charconv>
#include <system_error>

namespace cdm::io {

bool parse_decimal(const char *b, const char *e, double &v) {
    const auto r = std::from_chars(b, e, v);
    return r.ec == std::errc() && r.ptr == e && b != e;
}

} // namespace cdm::io
