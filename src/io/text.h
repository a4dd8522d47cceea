// Numbers in messages as a person writes them: "1000", "0.001", "1e+06",
// never std::to_string's "1000.000000".
#pragma once

#include <cstdio>
#include <string>

namespace cdm::io {

inline std::string number_text(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.10g", v);
    return buf;
}

} // namespace cdm::io
