#!/usr/bin/env bash
# The cable-sag example (cable_sag.c) as a user runs it, through the command
# line: the sag hidden in a simulated jig session, fitted with the plugin;
# the calibration it writes names the plugin and the effect's fingerprint,
# is refused where the plugin is not loaded (or is another version of it),
# and streamed through sim: with the same sag in the simulator's truth it
# brings the error against the truth down to the ADC's resolution.
set -euo pipefail
CDM=$1 PLUGIN=$2 DEVICE=$3
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
C_TRUE=4e-8 # 1/mm^2: 0.3 mm on a 200 mm horizontal cable (10 g/m at 0.1 N)
cat > "$T/truth.json" <<JSON
{"format": "cdm-calibration", "version": 1, "device": $(cat "$DEVICE"),
 "effects": [{"name": "cable_offset", "params": {"o1": 0.4, "o2": -0.3, "o3": 0.2, "o4": -0.5}},
             {"name": "cable_sag", "params": {"c_per_mm2": $C_TRUE}}]}
JSON

# The catalogue with the plugin: its unit and where it comes from.
"$CDM" calib effects --plugin "$PLUGIN" --json > "$T/effects.json"
python3 - "$T/effects.json" "$PLUGIN" <<'PY'
import json, os, sys
(e,) = [e for e in json.load(open(sys.argv[1])) if e["name"] == "cable_sag"]
assert e["parameters"][0]["unit"] == "1/mm^2", e
assert e["origin"] == os.path.realpath(sys.argv[2]), e
assert len(e["fingerprint"]) == 16, e
PY

# 1. A jig session with the sag (and pot offsets) hidden in it; the fit
#    with the plugin recovers c.
"$CDM" calib simulate "$T/jig.csv" --plugin "$PLUGIN" --truth "$T/truth.json" --holes 13 --pitch-mm 10 \
  --samples 40 --seed 3
"$CDM" calib diagnose "$T/jig.csv" --device "$DEVICE" --plugin "$PLUGIN" --effects cable_offset,cable_sag \
  --json "$T/d.json" --calibration "$T/cal.json" --quiet --no-search
python3 - "$T/d.json" "$T/cal.json" "$PLUGIN" "$C_TRUE" <<'PY'
import json, os, sys
r = json.load(open(sys.argv[1]))
p = r["params"]["cable_sag"]["c_per_mm2"]
truth = float(sys.argv[4])
# Within 5 standard errors of the truth: the fit's own uncertainty.
assert abs(p["value"] - truth) < 5 * p["std"], p
assert r["explained"], r["verdict"]
(e,) = [e for e in json.load(open(sys.argv[2]))["effects"] if e["name"] == "cable_sag"]
assert e["origin"] == os.path.realpath(sys.argv[3]), e
assert len(e["fingerprint"]) == 16 and int(e["fingerprint"], 16) >= 0, e
print("c = %.4g +- %.2g /mm^2 (truth %g); explained, chi2/dof %.3f" % (p["value"], p["std"], truth,
                                                                      r["chi2_per_dof"]))
PY

# The search, the plugin loaded, finds the sag as what is missing after the
# offsets alone.
"$CDM" calib diagnose "$T/jig.csv" --device "$DEVICE" --plugin "$PLUGIN" --effects cable_offset \
  --json "$T/d0.json" --quiet > /dev/null
python3 - "$T/d0.json" <<'PY'
import json, sys
rec = json.load(open(sys.argv[1]))["recommended"]
assert "cable_sag" in rec["effects"] and rec["explained"], rec["effects"]
PY

# 2. The calibration without the plugin: refused, naming the effect and the
#    plugin to load; with a changed fingerprint: refused, saying so.
if "$CDM" stream sim: --calibration "$T/cal.json" --seconds 0.2 2> "$T/err.txt"; then
  echo "a calibration with cable_sag loaded without its plugin" >&2; exit 1
fi
grep -q 'user effect "cable_sag" is not registered' "$T/err.txt"
grep -qF "$(realpath "$PLUGIN")" "$T/err.txt"
python3 - "$T/cal.json" "$T/cal_other.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
for e in c["effects"]:
    if e["name"] == "cable_sag":
        e["fingerprint"] = "0123456789abcdef"
json.dump(c, open(sys.argv[2], "w"))
PY
if "$CDM" stream sim: --plugin "$PLUGIN" --calibration "$T/cal_other.json" --seconds 0.2 2> "$T/err2.txt"; then
  echo "a calibration with another fingerprint loaded" >&2; exit 1
fi
grep -q "fingerprint is 0123456789abcdef" "$T/err2.txt"

# 3. The master hides the same sag and offsets (truth=), noise-free: the
#    error against the simulator's truth without a calibration, with the
#    fitted one, and with the truth itself as the calibration (the floor).
SIM="sim:?truth=$T/truth.json&noise=0&motion=random"
"$CDM" stream "$SIM" --plugin "$PLUGIN" --truth --json --seconds 1 > "$T/nominal.jsonl"
"$CDM" stream "$SIM" --plugin "$PLUGIN" --truth --json --seconds 1 --calibration "$T/cal.json" > "$T/cal.jsonl"
"$CDM" stream "$SIM" --plugin "$PLUGIN" --truth --json --seconds 1 --calibration "$T/truth.json" > "$T/floor.jsonl"
python3 - "$T/nominal.jsonl" "$T/cal.jsonl" "$T/floor.jsonl" "$T/d.json" <<'PY'
import json, sys
def rms(path):
    (s,) = [json.loads(l) for l in open(path) if '"summary"' in l]
    return max(s["truth_error_rms_mm"])
nominal, cal, floor = rms(sys.argv[1]), rms(sys.argv[2]), rms(sys.argv[3])
p = json.load(open(sys.argv[4]))["params"]
s_o = max(p["cable_offset"][k]["std"] for k in ("o1", "o2", "o3", "o4"))
s_c = p["cable_sag"]["c_per_mm2"]["std"]
# The floor: the ADC counts 0.01 mm, a uniform rounding of 0.0029 mm RMS per
# reading, which reaches x (out of the plane, >= 30 mm) amplified by at most
# ~3: under 0.01 mm. The fitted calibration adds the fit's uncertainty: 5
# standard errors of an offset (x amplification <= 3) and of c (times L^3,
# L <= 260 mm).
bound = floor + 5 * 3 * s_o + 5 * s_c * 260.0 ** 3
print("error against the truth, worst axis RMS: nominal %.4f mm, fitted calibration %.4f mm (bound %.4f), "
      "truth as calibration %.4f mm" % (nominal, cal, bound, floor))
assert floor < 0.01, floor
assert cal < bound, (cal, bound)
assert nominal > 10 * cal, (nominal, cal)
PY

# 4. The other commands take --plugin: a sim: hiding the effect by name,
#    and a Python module is refused with how to use it instead.
"$CDM" info "sim:?effects=cable_sag" --plugin "$PLUGIN" > /dev/null
if "$CDM" info "sim:?effects=cable_sag" 2> "$T/err3.txt"; then
  echo "sim: hid an effect nobody registered" >&2; exit 1
fi
"$CDM" record "sim:?effects=cable_sag&realtime=0" "$T/poses.csv" --plugin "$PLUGIN" --seconds 0.5 > /dev/null
test -s "$T/poses.csv"
set +e
"$CDM" bridge --dds sim: --plugin "$T/missing.so" --seconds 0.1 2> "$T/err4.txt"; rc=$?
"$CDM" stream sim: --plugin effect.py --seconds 0.1 2> "$T/err5.txt"; rc5=$?
set -e
test "$rc" = 1 && grep -q -- "--plugin $T/missing.so" "$T/err4.txt"
test "$rc5" = 2 && grep -q "Python effect is used from Python" "$T/err5.txt"
echo "cable_sag workflow: ok"
