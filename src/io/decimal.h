// Decimal numerals of a CSV field, read by std::from_chars: libstdc++ (GCC
// 12 and later) implements it with the fast_float algorithm, correctly
// rounded, no locale, no allocation.
#pragma once

namespace cdm::io {

// The double std::from_chars (general format) reads from exactly [b, e):
// true, with v set, when it reads a number there that ends at e; false
// otherwise (an empty field, trailing bytes, a value out of a double's
// range; v unspecified). "inf" and "nan" are numbers to std::from_chars:
// the dataset's checks refuse them with the row they are on.
bool parse_decimal(const char *b, const char *e, double &v);

} // namespace cdm::io
