#!/usr/bin/env bash
# The README's first command: set up, build, and show the whole product on
# the simulated master (the embedded default). Under two minutes on 2 cores
# once built.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
BUILD=${CDM_BUILD_DIR:-build}
CDM="$BUILD/src/cli/cdm"
OUT=${CDM_TOUR_DIR:-out/tour}
DEVICE=docs/examples/device.json
# The master in this tour hides a physical effect the nominal model lacks.
HIDDEN=${CDM_TOUR_EFFECT:-exit_pulley}
SIM="sim:?effects=$HIDDEN&effect_seed=7"
mkdir -p "$OUT"
step() { printf '\n\033[1m== %s\033[0m\n' "$*"; }

step "1. The simulated master, as any program sees it (cdm info, cdm stream)"
"$CDM" info sim:
"$CDM" stream sim: --seconds 3

step "2. A jig session (the seed's 25x25 plate, 5 heights, 100 samples) recorded through the protocol path"
"$CDM" record "$SIM&motion=jig&realtime=0" "$OUT/jig.csv" --jig

step "3. Diagnose the nominal model: where it fails, which effect is missing"
"$CDM" calib diagnose "$OUT/jig.csv" --device "$DEVICE" --json "$OUT/nominal.json" --report "$OUT/report-nominal"
# The model search's recommendation (the effects it lands on, comma-separated).
TOP=$(python3 -c "import json,sys; print(','.join(json.load(open(sys.argv[1]))['recommended']['effects']))" "$OUT/nominal.json")

step "4. Add the recommended effects ($TOP) and watch the error fall"
"$CDM" calib diagnose "$OUT/jig.csv" --device "$DEVICE" --effects "$TOP" --json "$OUT/model.json" \
  --before "$OUT/nominal.json" --report "$OUT/report"

step "5. Write the calibration"
"$CDM" calib fit "$OUT/jig.csv" --device "$DEVICE" --effects "$TOP" --out "$OUT/calibration.json" --quiet

step "6. Reopen the master with the calibration: poses against the simulator's truth"
"$CDM" stream "$SIM" --truth --seconds 3 --calibration "$OUT/calibration.json"

step "7. A planned tenth of the plate, diagnosed as it is recorded: it stops once the model is determined"
"$CDM" calib plan --positions 312 --out "$OUT/plan.csv" --quiet
"$CDM" record "$SIM&motion=jig&realtime=0&jig_plan=$OUT/plan.csv" "$OUT/planned.csv" --jig --plan "$OUT/plan.csv" \
  --live
"$CDM" calib fit "$OUT/planned.csv" --device "$DEVICE" --effects "$TOP" --out "$OUT/planned-calibration.json" --quiet

step "8. Its calibration checked on the whole session: measured against predicted error"
"$CDM" calib check "$OUT/jig.csv" --calibration "$OUT/planned-calibration.json" --report "$OUT/report-check" --quiet

step "Done"
echo "The report: $OUT/report/index.html (the nominal model's: $OUT/report-nominal/index.html;"
echo "  the planned session's calibration checked on the whole session: $OUT/report-check/index.html)"
echo "The calibration: $OUT/calibration.json; the dataset: $OUT/jig.csv"
