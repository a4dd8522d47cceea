#!/usr/bin/env bash
# Fuzzing with libFuzzer: runs every fuzz target for SECONDS each (default
# 20: CI's short bounded run; long runs by hand, e.g. `scripts/fuzz.sh 600`),
# starting from the binary seed corpus in tests/fuzz/corpus/TARGET. The
# targets come from the address-sanitizer build (build-san-address/: clang,
# -fsanitize=fuzzer-no-link,address,undefined over the whole library, so the
# fuzzer sees inside the parsers it attacks), configured by
# `scripts/sanitize.sh --configure address` if it is not there yet: CI's
# sanitizer stage and this one share its objects. New inputs go to a scratch
# corpus, never into the tree. A crash, a leak or a sanitizer report fails
# the run and leaves the input in build-san-address/crashes/TARGET/. Prints
# one line per target with its coverage (libFuzzer's "cov", edges reached).
set -euo pipefail
cd "$(dirname "$0")/.."
# Usage: scripts/fuzz.sh [SECONDS [TARGET...]]  (no TARGET: every target)
secs=${1:-20}
shift || true
only=("$@")
scripts/sanitize.sh --configure address
dir=${CDM_SAN_BUILD_PREFIX:-build-san}-address
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
