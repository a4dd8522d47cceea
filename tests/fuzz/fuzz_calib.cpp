// libFuzzer entry for the calibration-side parsers (clang only).
#include "fuzz_calib_body.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    fuzz_calib_one(data, size);
    return 0;
}
