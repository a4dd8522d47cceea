#!/usr/bin/env python3
"""A planned tenth of the seed's jig session against the whole session, and
against random and regular subsets of the same size (docs/calibration.md,
"Planning a session").

For each scenario (a simulated device with hidden effects): the whole plate
(25 x 25 holes, 5 heights, 100 samples) is simulated; `cdm calib plan` picks
N positions from the geometry and the catalogue alone (it is not told the
effects); a session planned in two steps (half for the catalogue, measured
and diagnosed, the other half planned on from it for the recommended model:
`calib plan --after`); the planned positions, random draws of N and a regular subset of N
(every k-th position in the plate's order) are simulated from the same truth;
each is fitted with the whole session's model (the hidden effects) and
  - checked on the whole session (`cdm calib check`: position_error_mm, each
    position's mean error, the jig's seating error in it), and
  - compared with the truth at 405 points of the jig's volume (the
    calibration's true error: the truth's readings placed by it).
Prints one table row per scenario and subset size. By hand (2-3 min):

    python3 tests/bench/bench_plan.py --cdm build/src/cli/cdm [--fractions 10,20,50] [--random 3] [--draws 1]

Needs the Python package on PYTHONPATH and CDM_LIBRARY (or an installed
libcdm) for the true error.
"""
import argparse
import json
import os
import random
import subprocess
import sys
import tempfile

import numpy as np

SCENARIOS = [
    ("exit_pulley + cable_gain", ["exit_pulley", "cable_gain"], []),
    ("two at once: anchor_position + cable_offset", ["anchor_position", "cable_offset"], []),
    ("noisy jig (0.06 mm): exit_pulley", ["exit_pulley"], ["--jig-tolerance-mm", "0.06"]),
    ("ripple: drum_eccentricity", ["drum_eccentricity"], []),
    ("plate holes and fixture 0.03 mm: cable_offset + pot_nonlinearity", ["cable_offset", "pot_nonlinearity"],
     ["--jig-hole-mm", "0.03", "--jig-fixture-mm", "0.03"]),
]


PLAN_FOR_THE_MODEL = False  # --plan-for-the-model: the planner told the hidden effects
DRAWS = 1  # --draws: noise draws of each planned and regular subset, averaged


def run(argv):
    r = subprocess.run(argv, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("failed: %s\n%s" % (" ".join(argv), r.stderr))
    return r.stdout


def positions(csv_path):
    """The dataset's positions {point: (x, y, z)} in the file's order."""
    seen = {}
    with open(csv_path) as f:
        next(f)
        for line in f:
            c = line.split(",", 5)
            seen.setdefault(int(c[0]), (float(c[1]), float(c[2]), float(c[3])))
    return seen


def write_plan(path, refs, samples):
    with open(path, "w") as f:
        f.write("x_ref,y_ref,z_ref,samples\n")
        for r in refs:
            f.write("%.4f,%.4f,%.4f,%d\n" % (r[0], r[1], r[2], samples))


def true_error(truth, cal_path):
    import cdm
    cal = cdm.Calibration.load(cal_path)
    e = []
    for x in np.linspace(30, 70, 5):
        for y in np.linspace(-60, 60, 9):
            for z in np.linspace(-60, 60, 9):
                e.append(np.subtract(cal.position(truth.lengths((x, y, z))), (x, y, z)))
    return float(np.sqrt((np.array(e) ** 2).sum(1).mean()))


def score(cdm_cli, d, name, data, effects, full, truth):
    cal = os.path.join(d, name + ".cal.json")
    chk = os.path.join(d, name + ".check.json")
    run([cdm_cli, "calib", "fit", data, "--effects", ",".join(effects), "--out", cal, "--quiet"])
    run([cdm_cli, "calib", "check", full, "--calibration", cal, "--json", chk, "--quiet"])
    pe = json.load(open(chk))["position_error_mm"]
    return float(np.sqrt(sum(pe[a]["rms"] ** 2 for a in "xyz"))), true_error(truth, cal)


def recommended(cdm_cli, data):
    """The model the data's diagnosis recommends, and the alternatives it
    names as equally good (within its BIC margin: anchor_position and
    holder_geometry move the same readings): a list of frozensets, the
    recommended first."""
    out = data + ".diag.json"
    run([cdm_cli, "calib", "diagnose", data, "--json", out, "--quiet"])
    r = json.load(open(out))["recommended"]
    return [frozenset(r["effects"])] + [frozenset(a) for a in r.get("alternatives", [])]


def read_plan(path):
    with open(path) as f:
        next(f)
        return [line for line in f if line.strip()]


def two_steps(cdm_cli, d, k, frac, n, truth_path, extra):
    """A session planned in two steps: half the positions for the whole
    catalogue, measured and diagnosed; the other half planned on from them
    (`calib plan --after`) for the model that half's diagnosis recommends,
    with the jig tolerance it estimated. Returns the whole plan (both
    halves), which is then simulated and scored as every subset is: the
    first half's noise there is a fresh draw, not the one diagnosed."""
    first = os.path.join(d, "first%d_%d.csv" % (k, frac))
    run([cdm_cli, "calib", "plan", "--positions", str(n // 2), "--out", first, "--quiet"])
    data = first + ".data.csv"
    run([cdm_cli, "calib", "simulate", data, "--truth", truth_path, "--seed", str(300 + k), "--plan", first] + extra)
    diag = data + ".json"
    run([cdm_cli, "calib", "diagnose", data, "--json", diag, "--quiet"])
    dj = json.load(open(diag))
    model = dj["recommended"]["effects"]
    # The jig's tolerance as the data shows it (the diagnosis's value): the
    # second half's weights.
    tol = dj["jig_tolerance_mm"]["value"]
    rest = os.path.join(d, "rest%d_%d.csv" % (k, frac))
    run([cdm_cli, "calib", "plan", "--positions", str(n - n // 2), "--after", first, "--out", rest, "--quiet",
         "--jig-tolerance-mm", "%.6f" % tol] + (["--effects", ",".join(model)] if model else []))
    both = os.path.join(d, "twosteps%d_%d.csv" % (k, frac))
    with open(both, "w") as f:
        f.write("x_ref,y_ref,z_ref,samples\n" + "".join(read_plan(first) + read_plan(rest)))
    return both


def scenario(cdm_cli, d, k, label, effects, extra, fractions, n_random):
    import cdm
    full = os.path.join(d, "full%d.csv" % k)
    truth_path = os.path.join(d, "truth%d.json" % k)
    sim = [cdm_cli, "calib", "simulate"]
    run(sim + [full, "--effects", ",".join(effects), "--effect-seed", str(10 + k), "--truth-out", truth_path,
               "--seed", str(100 + k)] + extra)
    truth = cdm.Calibration.load(truth_path)
    refs = list(positions(full).values())
    base = score(cdm_cli, d, "whole%d" % k, full, effects, full, truth)
    whole_model = recommended(cdm_cli, full)
    rows = []
    for frac in fractions:
        n = len(refs) // frac
        plan = os.path.join(d, "plan%d_%d.csv" % (k, frac))
        run([cdm_cli, "calib", "plan", "--positions", str(n), "--out", plan, "--quiet"] +
            (["--effects", ",".join(effects)] if PLAN_FOR_THE_MODEL else []))
        subsets = {"planned": plan, "two steps": two_steps(cdm_cli, d, k, frac, n, truth_path, extra)}
        rng = random.Random(k * 1000 + frac)
        for i in range(n_random):
            p = os.path.join(d, "random%d_%d_%d.csv" % (k, frac, i))
            write_plan(p, rng.sample(refs, n), 100)
            subsets["random%d" % i] = p
        p = os.path.join(d, "regular%d_%d.csv" % (k, frac))
        write_plan(p, refs[::frac][:n], 100)
        subsets["regular"] = p
        got = {}
        for name, plan_csv in subsets.items():
            # A random subset is one draw of positions and noise; the others
            # are measured DRAWS times (noise seeds) and averaged.
            scores = []
            for i in range(1 if name.startswith("random") else DRAWS):
                data = plan_csv + (".data.csv" if i == 0 else ".data%d.csv" % i)
                run(sim + [data, "--truth", truth_path, "--seed", str(200 + k + 1000 * i), "--plan", plan_csv] +
                    extra)
                scores.append(score(cdm_cli, d, "%s%d_%d_%d" % (name, k, frac, i), data, effects, full, truth))
            got[name] = (float(np.mean([c for c, _ in scores])), float(np.mean([t for _, t in scores])))
        # Whether the planned sessions' diagnoses recommend the whole
        # session's model ("alt.": as an alternative they name equally good).
        same = []
        for name in ("planned", "two steps"):
            got_model = recommended(cdm_cli, subsets[name] + ".data.csv")
            same.append("yes" if got_model[0] == whole_model[0] else
                        "alt." if whole_model[0] in got_model or got_model[0] in whole_model else "no")
        rnd = [got["random%d" % i] for i in range(n_random)]
        rows.append((label, frac, n, base, got["planned"], got["two steps"],
                     (float(np.mean([r[0] for r in rnd])), float(np.mean([r[1] for r in rnd]))), got["regular"],
                     "/".join(same)))
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cdm", default="build/src/cli/cdm")
    ap.add_argument("--fractions", default="10,20,50")
    ap.add_argument("--random", type=int, default=3)
    ap.add_argument("--plan-for-the-model", action="store_true",
                    help="tell the planner the hidden effects (--effects) instead of the whole catalogue")
    ap.add_argument("--draws", type=int, default=1,
                    help="noise draws of each planned and regular subset, averaged (a random subset: one each)")
    a = ap.parse_args()
    global PLAN_FOR_THE_MODEL, DRAWS
    PLAN_FOR_THE_MODEL = a.plan_for_the_model
    DRAWS = max(1, a.draws)
    fractions = [int(f) for f in a.fractions.split(",")]
    print("| scenario | 1/k | N | whole: check, true | planned | two steps | random (mean of %d) | regular | "
          "whole's model: planned/two steps |" % a.random)
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as d:
        for k, (label, effects, extra) in enumerate(SCENARIOS):
            for row in scenario(a.cdm, d, k, label, effects, extra, fractions, a.random):
                label_, frac, n = row[:3]
                print("| %s | 1/%d | %d | %s | %s |" % (label_, frac, n, " | ".join("%.4f, %.4f" % c for c in row[3:-1]),
                                                      row[-1]), flush=True)


if __name__ == "__main__":
    main()
