// libFuzzer entry point (clang only):
//   cmake -DCMAKE_CXX_COMPILER=clang++ ... && ./tests/fuzz/fuzz_protocol tests/data/protocol
#include <cstdlib>

#include "fuzz_body.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (cdm_fuzz::check_bytes(data, size) != 0) std::abort();
    return 0;
}
