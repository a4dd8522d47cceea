"""cdm_plan (experimental, since 1.2), `cdm calib plan` and `cdm calib
simulate --plan`: a planned session's positions are the plate's, distinct,
in walking order, each effect's test reported; the simulator measures
exactly them; bad plans are refused naming the line. How well a planned
session calibrates against random and regular subsets is measured by
tests/bench/bench_plan.py (docs/calibration.md, "Planning a session")."""
import os
import subprocess

import pytest

import cdm

JIG = {"holes": 7, "pitch_mm": 10.0, "heights_mm": [40, 55, 70], "samples": 20}
CLI_JIG = ["--jig-n", "7", "--jig-pitch", "10", "--jig-heights", "40,55,70", "--samples", "20"]


def cli(*args, **kw):
    return subprocess.run([os.environ["CDM_CLI"], *map(str, args)], capture_output=True, text=True, timeout=120, **kw)


def test_a_plan_is_on_the_plate_distinct_and_walkable():
    r = cdm.plan(30, **JIG)
    pos = r["positions"]
    assert len(pos) == 30 == len(set(map(tuple, pos))) == len(set(r["points"]))
    assert r["plate_positions"] == 7 * 7 * 3 and r["samples"] == 20
    grid = {-30 + 10 * i for i in range(7)}
    for x, y, z, s in pos:
        assert x in (40, 55, 70) and y in grid and z in grid and s == 20
    # Walking order: heights never go back down; within a height, rows
    # (y) never go back.
    heights = [p[0] for p in pos]
    assert heights == sorted(heights)
    for h in (40, 55, 70):
        ys = [p[1] for p in pos if p[0] == h]
        assert ys == sorted(ys)
    # Every effect the whole plate detects at its typical size, the plan
    # detects too (stage 1's job), and the report says how it was tested.
    for e in r["detectability"]:
        if e["reachable"]:
            assert e["detectable"] and e["power"] >= r["target_power"], e
    assert "non-central chi-square" in r["test"]
    assert {e["effect"] for e in r["design"]["excluded"]} == {"pot_drift"}
    # More positions predict a smaller error, and the whole plate the smallest.
    bigger = cdm.plan(120, **JIG)
    assert r["predicted_sigma_mm"]["whole_plate"] <= bigger["predicted_sigma_mm"]["plan"] <= \
        r["predicted_sigma_mm"]["plan"]
    assert cdm.plan(30, **JIG)["positions"] == pos  # deterministic


def test_simulate_measures_exactly_the_planned_positions(tmp_path):
    plan = tmp_path / "plan.csv"
    r = cli("calib", "plan", "--positions", 25, *CLI_JIG, "--out", plan, "--json", tmp_path / "plan.json", "--quiet")
    assert r.returncode == 0, r.stderr
    assert "predicted error over the workspace" in r.stdout
    lines = plan.read_text().splitlines()
    assert lines[0] == "x_ref,y_ref,z_ref,samples" and len(lines) == 26
    data = tmp_path / "d.csv"
    r = cli("calib", "simulate", data, "--holes", 7, "--pitch-mm", 10, "--heights", "40,55,70", "--plan", plan)
    assert r.returncode == 0, r.stderr
    rows = data.read_text().splitlines()[1:]
    assert len(rows) == 25 * 20
    seen = []
    for row in rows:
        ref = tuple(float(v) for v in row.split(",")[1:4])
        if not seen or seen[-1] != ref:
            seen.append(ref)
    assert seen == [tuple(float(v) for v in line.split(",")[:3]) for line in lines[1:]]


@pytest.mark.parametrize("text, words", [
    ("x,y,z,n\n40,0,0,5\n", "header"),
    ("x_ref,y_ref,z_ref,samples\n40,0,zero,5\n", ":2: \"zero\" is not a number"),
    ("x_ref,y_ref,z_ref,samples\n40,0,0\n", ":2: 4 values expected"),
    ("x_ref,y_ref,z_ref,samples\n", "lists no position"),
    ("x_ref,y_ref,z_ref,samples\n40,0,0,5,\n", ':2: "" is not a number'),
    ("x_ref,y_ref,z_ref,samples\n40,0,0,2.5\n", ":2: samples must be a whole number"),
    ("x_ref,y_ref,z_ref,samples\n6000,0,0,5\n", ":2: a reference beyond"),
    ("x_ref,y_ref,z_ref,samples\n40,0,0,5\n40,10,0,5\n40,0,0.0000,7\n", ":4: the position of line 2 again"),
])
def test_a_bad_plan_file_is_refused_naming_the_line(tmp_path, text, words):
    plan = tmp_path / "plan.csv"
    plan.write_text(text)
    r = cli("calib", "simulate", tmp_path / "d.csv", "--holes", 7, "--pitch-mm", 10, "--plan", plan)
    assert r.returncode == 2 and words in r.stderr, r.stderr
    assert not (tmp_path / "d.csv").exists()


def test_a_plan_file_may_start_with_a_byte_order_mark(tmp_path):
    """A spreadsheet's "CSV UTF-8" starts with one; it is no part of the header."""
    plan = tmp_path / "plan.csv"
    plan.write_bytes(b"\xef\xbb\xbfx_ref,y_ref,z_ref,samples\r\n40,0,0,5\r\n")
    r = cli("calib", "simulate", tmp_path / "d.csv", "--holes", 7, "--pitch-mm", 10, "--plan", plan)
    assert r.returncode == 0, r.stderr
    assert len((tmp_path / "d.csv").read_text().splitlines()) == 1 + 5


def test_a_repeated_height_is_refused():
    with pytest.raises(cdm.CdmError, match="jig_heights lists 50 mm twice"):
        cdm.plan(4, holes=3, pitch_mm=10.0, heights_mm=[50, 60, 50], samples=5)


def test_the_order_starts_at_the_lowest_height_and_rows_alternate():
    pos = cdm.plan(40, holes=7, pitch_mm=10.0, heights_mm=[70, 40, 55], samples=20)["positions"]
    assert [p[0] for p in pos] == sorted(p[0] for p in pos)
    rows = []  # (height, y) of each visited row, in order, with its z's
    for x, y, z, _ in pos:
        if not rows or rows[-1][0] != (x, y):
            rows.append(((x, y), []))
        rows[-1][1].append(z)
    for k, ((x, _), zs) in enumerate(rows):
        first = k == 0 or rows[k - 1][0][0] != x
        rank = 0 if first else rank + 1  # noqa: F821 - set on the first row of each height
        if len(zs) > 1:
            assert zs == (sorted(zs) if rank % 2 == 0 else sorted(zs, reverse=True)), (x, zs)


def test_odd_pitches_quiet_pots_and_nothing_to_plan(tmp_path):
    # Every digit of a reference goes into PLAN.csv: a pitch of 3.33333 mm
    # simulates back.
    plan = tmp_path / "plan.csv"
    r = cli("calib", "plan", "--positions", 20, "--jig-n", 7, "--jig-pitch", "3.33333", "--jig-heights", "40,55",
            "--out", plan, "--quiet")
    assert r.returncode == 0, r.stderr
    r = cli("calib", "simulate", tmp_path / "d.csv", "--holes", 7, "--pitch-mm", "3.33333", "--heights", "40,55",
            "--plan", plan)
    assert r.returncode == 0, r.stderr
    # Quiet pots and many samples: a non-centrality past the
    # non-central chi-square's series is power 1, not an error.
    q = cdm.plan(10, holes=25, pitch_mm=5.0, samples=1000, noise_mm=0.01, jig_tolerance_mm=0.005)
    assert all(e["power"] == 1.0 for e in q["detectability"] if e["reachable"])
    for effects in (["ellipsoid"], ["pot_drift"]):
        with pytest.raises(cdm.InvalidArgumentError) as e:
            cdm.plan(5, effects=effects, **JIG)
        assert "nothing to plan for" in str(e.value) and effects[0] in str(e.value)


def test_a_position_off_the_plate_or_too_many_positions(tmp_path):
    plan = tmp_path / "plan.csv"
    plan.write_text("x_ref,y_ref,z_ref,samples\n40,0,0,5\n40,3,0,5\n")
    r = cli("calib", "simulate", tmp_path / "d.csv", "--holes", 7, "--pitch-mm", 10, "--heights", "40,55", "--plan",
            plan)
    # refused before any file is written, as a bad option (exit 1: the library's refusal)
    assert r.returncode == 1 and "plan position 2 (40, 3, 0 mm) is not a hole" in r.stderr, r.stderr
    assert "invalid argument" in r.stderr and not (tmp_path / "d.csv").exists()
    with pytest.raises(cdm.InvalidArgumentError) as e:
        cdm.plan(1000, **JIG)
    assert "positions must be in 1..147" in str(e.value)
    with pytest.raises(cdm.InvalidArgumentError) as e:
        cdm.plan(10, holes=100, heights_mm=[30, 40, 50])
    assert "over the planner's 20000" in str(e.value)
    with pytest.raises(cdm.InvalidArgumentError) as e:
        cdm.plan(5, effects=["no_such_effect"], **JIG)
    assert "no_such_effect" in str(e.value)


def dataset_positions(path):
    """(point, x, y, z) -> rows of a dataset CSV, in first-appearance order."""
    import csv
    out = {}
    with open(path) as f:
        for r in csv.DictReader(f):
            k = (int(r["point"]), float(r["x_ref"]), float(r["y_ref"]), float(r["z_ref"]))
            out[k] = out.get(k, 0) + 1
    return list(out.items())


def test_record_walks_a_planned_session(tmp_path):
    """`cdm record --jig --plan` on the simulated master walking the same
    PLAN.csv (sim:'s jig_plan): the same positions, in the plan's order, with
    each its own samples, as `cdm calib simulate --plan` writes; the
    progress line names the height and the hole that come next."""
    plan = tmp_path / "plan.csv"
    rows = ["x_ref,y_ref,z_ref,samples", "40,-30,-30,7", "40,-30,0,12", "55,10,20,5", "70,0,0,9"]
    plan.write_text("\n".join(rows) + "\n")
    plate = "jig_n=7&jig_pitch=10&jig_heights=40,55,70"
    rec = tmp_path / "rec.csv"
    # Paced at 100 Hz (133 reports, 1.3 s): the progress line has time to show.
    r = cli("record", "sim:?rate=100&motion=jig&%s&jig_plan=%s" % (plate, plan), rec, "--jig", "--plan", plan)
    assert r.returncode == 0, r.stderr
    assert "4 of 4 jig positions (33 samples" in r.stdout, r.stdout
    assert "jig position 1/4: height 40 mm, hole y -30 z -30 mm" in r.stderr, r.stderr
    sim = tmp_path / "sim.csv"
    r = cli("calib", "simulate", sim, "--holes", 7, "--pitch-mm", 10, "--heights", "40,55,70", "--plan", plan)
    assert r.returncode == 0, r.stderr
    got = dataset_positions(rec)
    assert got == dataset_positions(sim)
    assert [(k[1], k[2], k[3], n) for k, n in got] == [(40, -30, -30, 7), (40, -30, 0, 12), (55, 10, 20, 5), (70, 0, 0, 9)]


def test_record_refuses_a_plan_that_cannot_be_walked(tmp_path):
    plan = tmp_path / "plan.csv"
    plan.write_text("x_ref,y_ref,z_ref,samples\n40,-30,-30,7\n")
    other = tmp_path / "other.csv"
    other.write_text("x_ref,y_ref,z_ref,samples\n40,-30,0,7\n")
    off = tmp_path / "off.csv"
    off.write_text("x_ref,y_ref,z_ref,samples\n40,-30,-30,7\n40,3,0,5\n")
    plate = "sim:?realtime=0&motion=jig&jig_n=7&jig_pitch=10&jig_heights=40,55,70"
    cases = [
        ([plate, tmp_path / "a.cdmrec", "--plan", plan], "a planned session is recorded with --jig"),
        ([plate + "&jig_plan=%s" % plan, tmp_path / "b.csv", "--jig", "--plan", other],
         "is not the simulator's jig_plan"),
        ([plate, tmp_path / "c.csv", "--jig", "--plan", off], "plan position 2 (40, 3, 0 mm) is not a hole"),
        ([plate + "&jig_plan=%s" % off, tmp_path / "d.csv", "--jig"], "plan position 2 (40, 3, 0 mm) is not a hole"),
        # The simulated master without the plan walks the whole plate: the labels would be wrong.
        ([plate, tmp_path / "e.csv", "--jig", "--plan", plan], "give it the plan too (jig_plan="),
    ]
    for args, words in cases:
        r = cli("record", *args)
        assert r.returncode == 2 and words in r.stderr, (args, r.returncode, r.stderr)
        assert not os.path.exists(args[1]), args[1]
    # The plan is an input: never written over, by the recorder or the simulator.
    before = plan.read_text()
    for args in (["record", plate + "&jig_plan=%s" % plan, plan, "--jig", "--plan", plan],
                 ["record", plate + "&jig_plan=%s" % plan, plan, "--jig"],
                 ["calib", "simulate", plan, "--holes", 7, "--pitch-mm", 10, "--heights", "40,55,70", "--plan", plan]):
        r = cli(*args)
        assert r.returncode != 0 and "input" in r.stderr, (args, r.returncode, r.stderr)
        assert plan.read_text() == before, args


def test_a_planned_tenth_beats_random_and_regular_tenths(tmp_path):
    """The small version of bench_plan.py: on a 9 x 9-hole plate at five
    heights (405 positions), with exit_pulley + cable_gain hidden, a tenth
    planned from the catalogue alone calibrates the device closer to the
    truth than each of five random tenths and the regular tenth (each
    fitted with the hidden effects; the true error at 125 points of the
    jig's volume). Fixed seeds: the same draws every run."""
    import random

    import numpy as np
    jig = ["--holes", 9, "--pitch-mm", 15]
    effects = "exit_pulley,cable_gain"
    full, truth_path = tmp_path / "full.csv", tmp_path / "truth.json"
    r = cli("calib", "simulate", full, "--effects", effects, "--effect-seed", 5, "--truth-out", truth_path,
            "--seed", 1, *jig)
    assert r.returncode == 0, r.stderr
    truth = cdm.Calibration.load(truth_path)
    plate = [k[1:] for k, _ in dataset_positions(full)]
    n = len(plate) // 10
    plan = tmp_path / "planned.plan"
    r = cli("calib", "plan", "--positions", n, "--jig-n", 9, "--jig-pitch", 15, "--out", plan, "--quiet")
    assert r.returncode == 0, r.stderr
    rng = random.Random(3)
    subsets = {"random%d" % i: rng.sample(plate, n) for i in range(5)}
    subsets["regular"] = plate[::len(plate) // n][:n]
    for name, refs in subsets.items():
        (tmp_path / (name + ".plan")).write_text(
            "x_ref,y_ref,z_ref,samples\n" + "".join("%r,%r,%r,100\n" % tuple(p) for p in refs))

    def true_error(name):
        data, cal = tmp_path / (name + ".csv"), tmp_path / (name + ".cal.json")
        r = cli("calib", "simulate", data, "--truth", truth_path, "--seed", 2, "--plan", tmp_path / (name + ".plan"),
                *jig)
        assert r.returncode == 0, r.stderr
        r = cli("calib", "fit", data, "--effects", effects, "--out", cal, "--quiet")
        assert r.returncode == 0, r.stderr
        c = cdm.Calibration.load(cal)
        grid = [(x, y, z) for x in np.linspace(30, 70, 5) for y in np.linspace(-60, 60, 5)
                for z in np.linspace(-60, 60, 5)]
        e = [np.subtract(c.position(truth.lengths(p)), p) for p in grid]
        return float(np.sqrt((np.array(e) ** 2).sum(1).mean()))

    planned = true_error("planned")
    others = {name: true_error(name) for name in subsets}
    assert all(planned < v for v in others.values()), (planned, others)


def test_python_plan_arguments_are_checked_not_truncated():
    """Counts are whole numbers (2.5 or True is refused, not truncated), a
    NaN is named, and effects may be one comma-separated string as the
    `cdm` command takes them."""
    for kw in ({"positions": 2.5}, {"positions": True}, {"positions": 4, "holes": 3.9}, {"positions": 4, "samples": "5"}):
        with pytest.raises(TypeError, match="whole number"):
            cdm.plan(**{"holes": 5, "heights_mm": [50, 60], **kw})
    with pytest.raises(ValueError, match="pitch_mm is nan"):
        cdm.plan(4, holes=5, heights_mm=[50, 60], pitch_mm=float("nan"))
    with pytest.raises(ValueError, match=r"measured\[0\]\[1\] is inf"):
        cdm.plan(4, holes=5, heights_mm=[50, 60], measured=[[50, float("inf"), 0]])
    with pytest.raises(TypeError, match="heights_mm must be numbers"):
        cdm.plan(4, holes=5, heights_mm="50,60")
    a = cdm.plan(6, holes=5, heights_mm=[50, 60], effects="exit_pulley,cable_gain", samples=10)
    b = cdm.plan(6.0, holes=5, heights_mm=[50, 60], effects=["exit_pulley", "cable_gain"], samples=10)
    assert a["positions"] == b["positions"] and len(a["positions"]) == 6
