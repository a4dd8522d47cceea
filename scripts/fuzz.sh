#!/usr/bin/env bash
# Fuzzing with libFuzzer: builds the whole library instrumented for coverage
# (clang, -fsanitize=fuzzer-no-link,address,undefined; build-fuzz/) and runs
# every fuzz target for SECONDS each (default 20: CI's short bounded run;
# long runs by hand, e.g. `scripts/fuzz.sh 600`), starting from the binary
# seed corpus in tests/fuzz/corpus/TARGET. New inputs go to a scratch corpus,
# never into the tree. A crash, a leak or a sanitizer report fails the run
# and leaves the input in build-fuzz/crashes/TARGET/. Prints one line per
# target with its coverage (libFuzzer's "cov", edges reached).
set -euo pipefail
cd "$(dirname "$0")/.."
# Usage: scripts/fuzz.sh [SECONDS [TARGET...]]  (no TARGET: every target)
secs=${1:-20}
shift || true
only=("$@")
dir=${CDM_FUZZ_BUILD_DIR:-build-fuzz}
if [ ! -f "$dir/build.ninja" ]; then
  CC=clang CXX=clang++ cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCDM_FUZZ=ON \
    -DCDM_BUILD_BINDINGS_TESTS=OFF -DCDM_BUILD_BENCHMARKS=OFF > /dev/null
fi
cmake --build "$dir" -j"$(nproc)" --target fuzz_all
status=0
targets=$(sed -n 's/^fuzz_target://p' "$dir/tests/fuzz/fuzz_targets.txt")
[ ${#only[@]} -gt 0 ] && targets="${only[*]}"
for target in $targets; do
  work=$(mktemp -d)
  crashes="$dir/crashes/$target"
  mkdir -p "$crashes"
  log="$dir/fuzz-$target.log"
  if "$dir/tests/fuzz/$target" -max_total_time="$secs" -print_final_stats=1 -artifact_prefix="$crashes/" \
       -timeout=10 -rss_limit_mb=2048 "$work" "tests/fuzz/corpus/$target" > "$log" 2>&1; then
    cov=$(grep -oE 'cov: [0-9]+' "$log" | tail -1)
    runs=$(grep -oE 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -oE '[0-9]+$' || echo "?")
    echo "fuzz: $target: ${secs}s, $runs runs, $cov, no crash"
  else
    echo "fuzz: $target: FAILED (log $log, input in $crashes/)"; tail -30 "$log"; status=1
  fi
  rm -rf "$work"
done
exit $status
