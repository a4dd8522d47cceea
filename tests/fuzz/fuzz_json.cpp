// The JSON reader every configuration file goes through: a refusal names
// source:line:column; nesting is bounded (no stack overflow).
#include <cstdlib>
#include <string>

#include "io/json.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const std::string text(reinterpret_cast<const char *>(data), size);
    cdm::io::JsonValue v;
    std::string err;
    if (!cdm::io::parse_json(text, "fuzz.json", v, err) && err.find("fuzz.json") == std::string::npos) std::abort();
    return 0;
}
