// One input through every calibration-side parser: the dataset CSV, the
// device description, the calibration JSON. Shared by the libFuzzer target
// and the deterministic mutation test. Must never crash, hang or hand out a
// non-finite number; errors are fine.
#pragma once
#include <cstddef>
#include <cstdint>

void fuzz_calib_one(const uint8_t *data, size_t size);
