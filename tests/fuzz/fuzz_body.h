// One body for the libFuzzer target and the deterministic mutation test:
// feeds bytes to every parser of the wire protocol and the replay format,
// and checks the round-trip invariants. Returns 0, or the number of the
// invariant that broke (the fuzzer aborts on it, the test fails on it).
#pragma once
#include <cstddef>
#include <cstdint>

namespace cdm_fuzz {
int check_bytes(const uint8_t *data, size_t size);
}
