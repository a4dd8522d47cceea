#!/usr/bin/env bash
# The beyond-catalogue workflow through the command line, as a user runs it:
# a cable offset and a dip worn into the pot tracks (docs/examples/worn_spot.c)
# hidden in simulated data.
set -euo pipefail
CDM=$1 PLUGIN=$2 DEVICE=$3
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cat > "$T/truth.json" <<JSON
{"format": "cdm-calibration", "version": 1, "device": $(cat "$DEVICE"),
 "effects": [{"name": "cable_offset", "params": {"o1": 0.4, "o2": -0.3, "o3": 0.2, "o4": -0.5}},
             {"name": "worn_spot", "params": {"depth_mm": -0.25, "centre_mm": 180.0, "width_mm": 6.0}}]}
JSON
"$CDM" calib simulate "$T/jig.csv" --plugin "$PLUGIN" --truth "$T/truth.json" --holes 13 --pitch-mm 10 --samples 40 --seed 3
# 1. Knowing only the catalogue: the search finds cable_offset, and after it
#    the residual stays unexplained; no catalogued effect explains it.
"$CDM" calib diagnose "$T/jig.csv" --device "$DEVICE" --json "$T/d1.json" --quiet
python3 - "$T/d1.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
rec = r["recommended"]
assert "cable_offset" in rec["effects"], rec["effects"]
assert not rec["explained"] and not rec["negligible_only"], "a worn spot must leave the catalogue's best model unexplained"
assert all(not c["explained_after"] for c in rec["candidates"]), "no catalogued effect may explain a worn spot"
print("unexplained after", " + ".join(rec["effects"]), "; findings:",
      [f["text"] for f in r["unexplained_structure"]["findings"]][:3])
PY
# 2. The user's effect, from the plugin (its centre and width fitted from
#    the plugin's initial values), explains it.
"$CDM" calib diagnose "$T/jig.csv" --device "$DEVICE" --plugin "$PLUGIN" --effects cable_offset,worn_spot \
  --json "$T/d2.json" --quiet
python3 - "$T/d2.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
p = r["params"]["worn_spot"]
# Within 5 standard errors of the truth: the fit's own uncertainty.
for k, truth in (("depth_mm", -0.25), ("centre_mm", 180.0), ("width_mm", 6.0)):
    assert abs(p[k]["value"] - truth) < 5 * p[k]["std"] + 1e-9, (k, p[k])
assert r["explained"], r["verdict"]
assert r["recommended"]["effects"] == ["cable_offset", "worn_spot"] or \
    sorted(r["recommended"]["effects"]) == ["cable_offset", "worn_spot"], r["recommended"]["effects"]
print("explained with the plugin: chi2/dof %.3f, depth %.4f mm at %.2f mm, width %.2f mm" % (
    r["chi2_per_dof"], p["depth_mm"]["value"], p["centre_mm"]["value"], p["width_mm"]["value"]))
PY
