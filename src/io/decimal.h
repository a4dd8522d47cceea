// Decimal numerals of a CSV field as std::from_chars reads them, faster on
// the form jig files hold ("-123.4567").
#pragma once

namespace cdm::io {

// The double std::from_chars (general format) reads from exactly [b, e):
// true, with v set, when it reads a number there that ends at e; false
// otherwise (v unspecified). A field of the form [-]digits[.digits] with at
// most 15 digits in all is read by Clinger's fast path: its digits are an
// integer below 10^15 < 2^53 and its scale a power of ten up to 10^15, both
// exact doubles, so one IEEE division gives the correctly rounded value,
// which is what std::from_chars returns. Any other field goes to
// std::from_chars itself.
bool parse_decimal(const char *b, const char *e, double &v);

} // namespace cdm::io
