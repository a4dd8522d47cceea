"""A jig session that knows when to stop: `cdm record --jig --live` diagnoses
the data as it comes, stops by itself once the model is determined (the
same recommended model for --stable updates, the predicted error under
--target-mm at every position of the session, none of them extrapolated),
and until then names the holes to measure next (cdm_plan planning on from
the measured positions). Every sample kept is in the dataset whatever the
analysis does; a replay gives the same updates and stops at the same
position."""
import csv
import json
import os
import subprocess

import pytest

import cdm

# A small plate (9 x 9 holes, 15 mm apart, the default five heights: 405
# positions) with two hidden effects; unpaced, so the reader waits for
# each update and the session is reproducible.
SIM = "sim:?effects=exit_pulley,cable_gain&effect_seed=7&motion=jig&jig_n=9&jig_pitch=15&seed=3"
PLATE = 9 * 9 * 5
# The simulated master's geometry, as it reports it (the live analysis's
# default device).
DEVICE = {"a_mm": 150, "b_mm": 150, "m_mm": 30}


def cli(*args, **kw):
    return subprocess.run([os.environ["CDM_CLI"], *map(str, args)], capture_output=True, text=True, timeout=300, **kw)


def positions_and_rows(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return len({r["point"] for r in rows}), len(rows)


def live_record(uri, out, *extra):
    r = cli("record", uri, out, "--jig", "--live", "--json", *extra)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), r.stderr


@pytest.fixture(scope="module")
def full_session(tmp_path_factory):
    """The whole plate, recorded without the live analysis, and its diagnosis."""
    d = tmp_path_factory.mktemp("full")
    data, device = d / "full.csv", d / "device.json"
    device.write_text(json.dumps(DEVICE))
    r = cli("record", SIM + "&realtime=0", data, "--jig")
    assert r.returncode == 0, r.stderr
    return data, device, cdm.diagnose(data, device)


def test_the_session_stops_by_itself_with_the_full_sessions_model(tmp_path, full_session):
    full, device, diagnosis = full_session
    data = tmp_path / "live.csv"
    summary, err = live_record(SIM + "&realtime=0", data)
    live = summary["live"]
    assert live["stopped"] and "stop: the model is determined" in err
    assert summary["positions"] < PLATE == summary["of"]
    # The model the whole plate recommends.
    assert live["model"] == diagnosis["recommended"]["effects"]
    last = live["updates"][-1]
    assert last["decision"] == "stop" and (last["explained"] or last["negligible_only"])
    assert last["same_for"] >= live["stable"]
    assert last["outside_measured_volume"] == 0
    assert last["predicted_radius95_mm"]["worst"] <= live["target_mm"]
    # Until the stop, each update said where to measure next: holes of
    # the session not measured yet.
    for u in live["updates"][:-1]:
        assert u["decision"] == "next" and len(u["next"]) == 5
        assert all(p[0] in (30, 40, 50, 60, 70) and abs(p[1]) <= 60 and abs(p[2]) <= 60 for p in u["next"])
    # Nothing is lost: every position kept is in the file with its samples.
    n, rows = positions_and_rows(data)
    assert n == summary["positions"] and rows == summary["samples"] == 100 * n
    # And its accuracy is the full session's: the calibration fitted on the
    # stopped session, checked on the whole plate, holds there as its
    # accuracy map predicted (the check's chi-square test of the position
    # errors against the calibration's covariance, at its level).
    cal = tmp_path / "cal.json"
    cdm.fit(data, device, live["model"], calibration_out=cal)
    check = cdm.check(full, cal)
    assert check["predicted"]["as_predicted"], check["predicted"]["text"]
    assert check["failing"]["count"] == 0


def test_a_replay_gives_the_same_updates_and_stop(tmp_path):
    rec = tmp_path / "session.cdmrec"
    r = cli("record", SIM + "&realtime=0", rec)
    assert r.returncode == 0, r.stderr
    # A replay does not know the plate: it is given as the sim: URI has it.
    a, _ = live_record(f"replay:{rec}?speed=0", tmp_path / "a.csv", "--jig-n", 9, "--jig-pitch", 15)
    b, _ = live_record(SIM + "&realtime=0", tmp_path / "b.csv")

    def strip(s):
        return [{k: v for k, v in u.items() if k != "seconds"} for u in s["live"]["updates"]]

    assert strip(a) == strip(b) and a["positions"] == b["positions"]
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


def test_a_paced_session_keeps_every_sample_while_the_analysis_runs(tmp_path):
    # Paced by the clock: the analysis runs beside the reader and never
    # holds it; the session ends by the stop or with the plan, and either
    # way every kept position is in the file.
    data = tmp_path / "paced.csv"
    uri = "sim:?effects=exit_pulley&motion=jig&jig_n=5&jig_pitch=30&jig_heights=30,50,70&rate=5000"
    summary, _ = live_record(uri, data, "--live-every", 10)
    assert summary["stats"]["dropped"] == 0 and summary["short_dwells"] == 0
    assert summary["live"]["stopped"] or summary["positions"] == summary["of"] == 75
    n, rows = positions_and_rows(data)
    assert n == summary["positions"] and rows == 100 * n


def test_a_target_out_of_reach_runs_the_whole_plan(tmp_path):
    summary, err = live_record(SIM + "&realtime=0", tmp_path / "d.csv", "--target-mm", "0.000001")
    assert not summary["live"]["stopped"] and summary["positions"] == PLATE
    assert "stop:" not in err and "next: measure these holes" in err


@pytest.mark.parametrize("args, words", [
    (["--jig", "--target-mm", "0.1"], "--target-mm requires --live"),
    (["--live"], "a live analysis is of a jig session (--jig)"),
    (["--jig", "--live", "--stable", "0"], "--stable"),
])
def test_live_options_are_checked(tmp_path, args, words):
    r = cli("record", SIM + "&realtime=0", tmp_path / "x.csv", *args)
    assert r.returncode == 2 and words in r.stderr, r.stderr
    assert not (tmp_path / "x.csv").exists()


def test_the_device_file_is_checked_before_anything_opens(tmp_path):
    """--device is read before the session (a missing or bad file, or another
    frame than the device's, is a usage error and nothing is written), and
    is an input: never the output."""
    dev = tmp_path / "dev.json"
    dev.write_text(json.dumps(DEVICE))
    wide = tmp_path / "wide.json"
    wide.write_text(json.dumps({**DEVICE, "a_mm": 200}))
    bad = tmp_path / "bad.json"
    bad.write_text('{"a_mm": 150, "b_mm": 150,\n "m_mm": -30}')
    out = tmp_path / "x.csv"
    for device, words in [(tmp_path / "none.json", "cannot open"), (bad, "bad.json:2:"),
                          (wide, "a_mm 200 (" + str(wide) + ") vs 150 (the device)")]:
        r = cli("record", SIM + "&realtime=0", out, "--jig", "--live", "--device", device)
        assert r.returncode == 2 and words in r.stderr, r.stderr
        assert not out.exists() and not list(tmp_path.glob(".x.csv*"))
    r = cli("record", SIM + "&realtime=0", dev, "--jig", "--live", "--device", dev)
    assert r.returncode == 2 and "not writing over it" in r.stderr, r.stderr
    assert json.loads(dev.read_text()) == DEVICE


def test_planning_on_from_the_measured_positions():
    jig = {"holes": 7, "pitch_mm": 10.0, "heights_mm": [40, 55, 70], "samples": 20}
    measured = [p[:3] for p in cdm.plan(10, **jig)["positions"]]
    allowed = [[70.0, y, z] for y in (-30.0, 0.0, 30.0) for z in (-30.0, 0.0, 30.0)]
    r = cdm.plan(4, measured=measured, allowed=allowed, **jig)
    picks = [p[:3] for p in r["positions"]]
    assert r["measured"] == 10 and len(picks) == 4
    assert all(p in allowed and p not in measured for p in picks)
    # The measured positions' information counts: planning on from them
    # predicts a smaller error than four picks from nothing.
    alone = cdm.plan(4, allowed=allowed, **jig)
    assert r["predicted_sigma_mm"]["plan"] < alone["predicted_sigma_mm"]["plan"]
    with pytest.raises(cdm.CdmError, match="at most 9"):
        cdm.plan(10, allowed=allowed, **jig)
    with pytest.raises(cdm.CdmError, match=r"\"measured\": .*\(41, 0, 0 mm\) is not a hole"):
        cdm.plan(3, measured=[[41, 0, 0]], **jig)


def test_a_jig_plan_names_its_plate():
    import ctypes
    from cdm import _native
    L = _native.lib()
    plan = ctypes.c_void_p()
    assert L.cdm_jig_plan_create((SIM + "&jig_heights=35,45").encode(), 0, 0.0, None, 0, 0, ctypes.byref(plan)) == 0
    try:
        holes, pitch, n = ctypes.c_int(), ctypes.c_double(), ctypes.c_size_t()
        # First without room for the heights: how many there are.
        assert L.cdm_jig_plan_plate(plan, ctypes.byref(holes), ctypes.byref(pitch), None, 0, ctypes.byref(n)) == 0
        assert (holes.value, pitch.value, n.value) == (9, 15.0, 2)
        heights = (ctypes.c_double * 2)()
        assert L.cdm_jig_plan_plate(plan, None, None, heights, 2, ctypes.byref(n)) == 0
        assert list(heights) == [35.0, 45.0]
        assert L.cdm_jig_plan_plate(None, None, None, None, 0, None) == cdm.Error.CDM_ERR_INVALID_ARG
    finally:
        L.cdm_jig_plan_free(plan)
