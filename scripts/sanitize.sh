#!/usr/bin/env bash
# The C and C++ tests again under AddressSanitizer + UndefinedBehaviorSanitizer
# and under ThreadSanitizer (the reader thread, the sequence lock, hot-plug).
# Run by CI after the README's test command. Warnings are errors in the
# plain build; here GCC's instrumented inlining gives false "may be used
# uninitialized" inside libstdc++, so they stay warnings.
set -euo pipefail
cd "$(dirname "$0")/.."
for san in address,undefined thread; do
  dir=${CDM_SAN_BUILD_PREFIX:-build-san}-${san%%,*}
  cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCDM_SANITIZE="$san" \
        -DCDM_BUILD_BINDINGS_TESTS=OFF -DCDM_BUILD_BENCHMARKS=OFF -DCDM_WERROR=OFF > /dev/null
  cmake --build "$dir" -j"$(nproc)"
  # jig_*, model_*, io_*, device_*, calib_*, api_* are the C/C++ programs; the bindings' tests run
  # in the plain build (an instrumented libcdm inside python or mono needs
  # the sanitizer runtime preloaded, which tests nothing more of our code).
  ctest --test-dir "$dir" -R '^(jig|model|io|device|calib|api|fuzz)_' --output-on-failure -j"$(nproc)"
done
