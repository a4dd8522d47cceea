#!/usr/bin/env python3
"""The blind regression set, by hand (not a ctest: minutes, not seconds).

Draws jig datasets with `cdm calib simulate` (hidden effects at random realistic magnitudes,
alone and together, clean, noisy, sparse, plates with hole and fixture errors), diagnoses each
with `cdm calib diagnose --json`, and scores the recommendation against the truth:

  exact       the recommended effects are the hidden ones
  equivalent  the hidden set is among the recommendation's alternatives (models the data
              cannot tell from it: anchor_position and holder_geometry for a holder that
              only translates, and the like), or every hidden effect not recommended is one
              the recommended model contains in the data's eyes (no candidate row left for it
              after the gauge, or its row says the model's effects reproduce it)
  missing     a hidden effect is not recommended (nor an equivalent)
  extra       an effect is recommended that was not hidden
  explained   the recommended model's verdict

Two builds can be run side by side on the same files (--vs OTHER_CDM): the table then gives both
and lists every case whose outcome differs. The cases are fixed by --seed, so a run is repeatable;
the effect magnitudes are the simulator's own random draws (--effect-seed), not chosen to pass.

    python3 tests/regression/blind.py --cdm build/src/cli/cdm --cases 60 --jobs 2 --out /tmp/blind
    python3 tests/regression/blind.py --cdm NEW --vs OLD --cases 60 --out /tmp/blind

Exit status 0 (the numbers are for a person to read; nothing here is pass/fail).
"""
import argparse
import json
import os
import random
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

CATALOGUE = ["cable_offset", "cable_gain", "exit_pulley", "cable_stretch", "pot_nonlinearity",
             "anchor_position", "holder_geometry", "jig_misalignment", "drum_eccentricity", "pot_drift"]
# Inseparable by construction: the same readings for every position (a holder that only
# translates moves every cable as the anchors would). A recommendation of one for the other
# is right.
SAME = [{"anchor_position", "holder_geometry"}]

JIGS = {
    "full": ["--holes", "25", "--pitch-mm", "5", "--samples", "100"],
    "half": ["--holes", "13", "--pitch-mm", "10", "--samples", "40"],
    "sparse": ["--holes", "13", "--pitch-mm", "10", "--samples", "10", "--heights", "30,50,70"],
}


def draw_cases(n, seed, full_share, small, hysteresis=False):
    rng = random.Random(seed)
    cases = []
    for k in range(n):
        r = rng.random()
        hidden = [] if r < 0.12 else rng.sample(CATALOGUE, 1 if r < 0.55 else 2 if r < 0.9 else 3)
        jig = "full" if rng.random() < full_share else rng.choice(["half", "half", "sparse"])
        noise = rng.choice([0.05, 0.05, 0.05, 0.25])
        plate = rng.random() < 0.3
        scale = 1.0 if not small else rng.choice([1.0, 1.0, 0.3, 0.3, 0.1])
        hyst = rng.choice([0.0, 0.0, 0.01, 0.02, 0.04]) if hysteresis else 0.0
        cases.append({"id": f"c{k:03d}", "hidden": hidden, "jig": jig, "noise": noise, "plate": plate,
                      "seed": rng.randrange(1, 10**6), "effect_seed": rng.randrange(1, 10**6), "scale": scale,
                      "hysteresis": hyst})
    return cases


def simulate(cdm, case, path):
    argv = [cdm, "calib", "simulate", path, "--seed", str(case["seed"]), "--noise-mm", str(case["noise"])] + JIGS[case["jig"]]
    if case["hidden"] and case.get("scale", 1.0) != 1.0:
        # The simulator's own draw of the magnitudes (a 2 x 2 jig is enough to have it write
        # them), every parameter but a period scaled down, then simulated as the true model.
        truth = path + ".truth.json"
        subprocess.run([cdm, "calib", "simulate", path, "--effects", ",".join(case["hidden"]), "--effect-seed",
                        str(case["effect_seed"]), "--truth-out", truth, "--holes", "2", "--samples", "1",
                        "--heights", "30,40"], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        with open(truth) as f:
            t = json.load(f)
        for e in t["effects"]:
            e["params"] = {k: v if k == "period" else v * case["scale"] for k, v in e["params"].items()}
        with open(truth, "w") as f:
            json.dump(t, f)
        argv += ["--truth", truth]
    elif case["hidden"]:
        argv += ["--effects", ",".join(case["hidden"]), "--effect-seed", str(case["effect_seed"])]
    if case["plate"]:
        argv += ["--jig-hole-mm", "0.03", "--jig-fixture-mm", "0.03"]
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    if case.get("hysteresis", 0.0) > 0:
        add_per_position_offsets(path, case["hysteresis"], case["seed"])


def add_per_position_offsets(path, sd, seed):
    """Each position's readings offset per cable by N(0, sd^2), the same for all its samples (a
    pot's hysteresis, a wiper's offset per approach), written through a temporary beside the file."""
    rng = random.Random(seed)
    tmp = path + ".tmp"
    with open(path) as f, open(tmp, "w") as g:
        header = f.readline()
        g.write(header)
        cols = header.strip().split(",")
        idx = [cols.index(c) for c in ("l1", "l2", "l3", "l4")]
        point, off = None, [0.0] * 4
        for line in f:
            v = line.rstrip("\n").split(",")
            if v[0] != point:
                point, off = v[0], [rng.gauss(0.0, sd) for _ in range(4)]
            for k, i in enumerate(idx):
                v[i] = "%.4f" % (float(v[i]) + off[k])
            g.write(",".join(v) + "\n")
    os.replace(tmp, path)


def canon(effects):
    s = set(effects)
    for group in SAME:
        if s & group:
            s = (s - group) | {"+".join(sorted(group))}
    return s


def absorbed(rec, name):
    """A hidden effect the recommended model already contains in the data's eyes: the
    diagnosis lists no candidate for it (nothing left to fit after the gauge: jig_misalignment
    beside anchor_position, cable_stretch beside cable_gain and pot_nonlinearity), or one that
    the model's own effects reproduce (confused_with)."""
    rows = [c for c in rec.get("candidates", []) if c["effect"] == name]
    return not rows or all(set(c.get("confused_with", [])) & set(rec["effects"]) for c in rows)


def score(case, js):
    rec = js["recommended"]
    got, want = canon(rec["effects"]), canon(case["hidden"])
    alts = [canon(a) for a in rec.get("alternatives", [])]
    missing = [e for e in case["hidden"] if e not in rec["effects"] and not canon([e]) <= got]
    outcome = ("exact" if got == want else "equivalent" if want in alts or (
        got <= want and all(absorbed(rec, e) for e in missing)) else "wrong")
    return {"outcome": outcome, "missing": sorted(want - got) if outcome == "wrong" else [],
            "extra": sorted(got - want) if outcome == "wrong" else [], "explained": bool(rec["explained"]),
            "recommended": rec["effects"], "x_rms": rec["error_mm"]["x"]["rms"],
            "floor": rec["noise_floor_mm"][0]}


def diagnose(cdm, csv, out_json):
    t0 = time.time()
    p = subprocess.run([cdm, "calib", "diagnose", csv, "--quiet", "--json", out_json],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        return None, time.time() - t0, p.stderr.strip()[-300:]
    with open(out_json) as f:
        return json.load(f), time.time() - t0, ""


def run_case(args, case):
    csv = os.path.join(args.out, case["id"] + ".csv")
    simulate(args.cdm, case, csv)
    res = {"case": case}
    for tag, cdm in [("a", args.cdm)] + ([("b", args.vs)] if args.vs else []):
        js, secs, err = diagnose(cdm, csv, os.path.join(args.out, f"{case['id']}.{tag}.json"))
        res[tag] = score(case, js) if js else {"outcome": "error", "error": err}
        res[tag]["seconds"] = secs
    if not args.keep:
        os.remove(csv)
    return res


def summary(results, tag):
    rows = [r[tag] for r in results]
    n = len(rows)
    count = lambda pred: sum(1 for r in rows if pred(r))
    ok = count(lambda r: r["outcome"] in ("exact", "equivalent"))
    return (f"{ok}/{n} right ({count(lambda r: r['outcome'] == 'exact')} exact, "
            f"{count(lambda r: r['outcome'] == 'equivalent')} equivalent), "
            f"{count(lambda r: r.get('missing'))} with a hidden effect missed, "
            f"{count(lambda r: r.get('extra'))} with an effect added, "
            f"{count(lambda r: r['outcome'] == 'error')} errors; "
            f"explained {count(lambda r: r.get('explained'))}/{n}; "
            f"{sum(r['seconds'] for r in rows):.0f} s of diagnosis")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cdm", required=True, help="the cdm command to judge")
    ap.add_argument("--vs", help="a second cdm command, run on the same files")
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--seed", type=int, default=1, help="draws the cases")
    ap.add_argument("--full-share", type=float, default=0.2, help="share of full 25 x 25 x 5 x 100 jigs")
    ap.add_argument("--small", action="store_true",
                    help="scale some cases' hidden magnitudes down (x0.3, x0.1): effects near detectability")
    ap.add_argument("--hysteresis", action="store_true",
                    help="give some cases a per-position error per cable (sd 0.01, 0.02, 0.04 mm): a pot's hysteresis")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", required=True, help="directory for the files (created)")
    ap.add_argument("--keep", action="store_true", help="keep the CSV files")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    cases = draw_cases(args.cases, args.seed, args.full_share, args.small, args.hysteresis)
    with ThreadPoolExecutor(args.jobs) as ex:
        results = list(ex.map(lambda c: run_case(args, c), cases))
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)
    for r in results:
        c, a = r["case"], r["a"]
        line = (f"{c['id']} {c['jig']:6s} noise {c['noise']:.2f}{' plate' if c['plate'] else '      '} x{c['scale']:<3g} h{c['hysteresis']:<4g} "
                f"hidden {','.join(c['hidden']) or '-':50s} a: {a['outcome']:10s} {','.join(a.get('recommended', [])) or '-'}"
                f"{'' if a.get('explained') else ' (not explained)'}")
        if args.vs:
            b = r["b"]
            line += f" | b: {b['outcome']:10s} {','.join(b.get('recommended', [])) or '-'}{'' if b.get('explained') else ' (not explained)'}"
            if (a["outcome"], a.get("explained"), a.get("recommended")) != (b["outcome"], b.get("explained"), b.get("recommended")):
                line += "   <- differs"
        print(line)
    print()
    print("a:", summary(results, "a"))
    if args.vs:
        print("b:", summary(results, "b"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
