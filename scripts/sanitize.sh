#!/usr/bin/env bash
# The C and C++ tests again under AddressSanitizer + UndefinedBehaviorSanitizer
# and under ThreadSanitizer (the reader thread, the sequence lock, hot-plug).
# Run by CI after the README's test command.
#
#   scripts/sanitize.sh [address] [thread]    build and test (default: both)
#   scripts/sanitize.sh --configure address   configure only (scripts/fuzz.sh)
#
# address: clang, ASan + UBSan, and libFuzzer's coverage instrumentation
# (-DCDM_FUZZ=ON) in one build, build-san-address/: its tests here, and the
# fuzz targets scripts/fuzz.sh runs, come from the same objects (CI builds
# the library three times, not four, besides the wheel test's own build;
# on CI's 2 cores clang's build took 6.75 min where GCC's ASan build took
# 15.2, docs/testing.md "CI's time"). thread: GCC, TSan, build-san-thread/;
# warnings stay warnings there, as GCC's instrumented inlining gives false
# "may be used uninitialized" inside libstdc++.
set -euo pipefail
cd "$(dirname "$0")/.."
prefix=${CDM_SAN_BUILD_PREFIX:-build-san}

# Configured every time (a few seconds once configured, nothing rebuilt when
# nothing changed), so a directory left by an older script or other options
# is brought to these; the compilers are named, not taken from CC/CXX.
configure() {
  local dir=$prefix-$1
  local common=(-G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
                -DCDM_BUILD_BINDINGS_TESTS=OFF -DCDM_BUILD_BENCHMARKS=OFF -DCDM_BUILD_CSHARP=OFF)
  case $1 in
    address) cmake -S . -B "$dir" "${common[@]}" -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
               -DCDM_SANITIZE=address,undefined -DCDM_FUZZ=ON -DCDM_WERROR=ON > /dev/null ;;
    thread)  cmake -S . -B "$dir" "${common[@]}" -DCMAKE_C_COMPILER=gcc -DCMAKE_CXX_COMPILER=g++ \
               -DCDM_SANITIZE=thread -DCDM_FUZZ=OFF -DCDM_WERROR=OFF > /dev/null ;;
  esac
}
check() {
  case $1 in
    address|thread) ;;
    *) echo "sanitize.sh: unknown sanitizer '$1' (address or thread)" >&2; exit 2 ;;
  esac
}

if [ "${1:-}" = "--configure" ]; then
  [ $# -eq 2 ] || { echo "usage: sanitize.sh --configure address|thread" >&2; exit 2; }
  check "$2"
  configure "$2"
  exit 0
fi
sans=("$@")
[ ${#sans[@]} -gt 0 ] || sans=(address thread)
for san in "${sans[@]}"; do check "$san"; done
for san in "${sans[@]}"; do
  configure "$san"
  dir=$prefix-$san
  cmake --build "$dir" -j"$(nproc)"
  # jig_*, model_*, io_*, device_*, calib_*, api_*, fuzz_* and umockdev_*
  # (the real hidapi and libudev on the emulated master) are the C/C++
  # programs, with cli_live_threads (the `cdm` command's live jig analysis,
  # its own threads); the bindings' tests run in the plain build (an instrumented
  # libcdm inside python or mono needs the sanitizer runtime preloaded,
  # which tests nothing more of our code). Under TSan only the `cdm`
  # command's umockdev tests: the others hold umockdev's testbed in the
  # test's own process, where TSan reports races between glib's and
  # umockdev's uninstrumented threads and refuses the threads the crash
  # cases start after a fork (docs/testing.md, "Under the sanitizers").
  umock='umockdev'
  [ "$san" = thread ] && umock='umockdev_cli'
  ctest --test-dir "$dir" -R "^((jig|model|io|device|calib|api|fuzz|$umock)_|cli_live_threads$)" -E '^umockdev_(python|csharp)_' \
        --output-on-failure -j"$(nproc)"
done
