"""cdm_check (experimental, since 1.2): a calibration applied as it is to
another jig session of the same device, only the jig placed anew.

Every session here is simulated from one true device (exit_pulley hidden,
--truth-out); the second session's jig is bolted on turned and shifted
(a jig_misalignment added to the truth), with other noise."""
import ctypes
import json
import math
import os
import subprocess

import pytest

import cdm
from cdm import _native
from conftest import simulate_jig

DEVICE_JSON = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples", "device.json")
CDM_ERR_INVALID_ARG, CDM_ERR_IO, CDM_ERR_PARSE = -1, -3, -11
# The second session's jig: turned by 0.2 degree about z and 0.1 about y,
# shifted by half a millimetre (a jig bolted on by hand).
MOVED = {"rx": 0.0, "ry": 1.7e-3, "rz": 3.5e-3, "tx": 0.4, "ty": -0.5, "tz": 0.3}
JIG = ("--holes", "7", "--heights", "40,55,70", "--samples", "10")


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    d = tmp_path_factory.mktemp("check")
    simulate_jig(d / "a.csv", "--device", DEVICE_JSON, "--effects", "exit_pulley", "--effect-seed", "3",
                 "--truth-out", d / "truth.json", "--seed", "11", *JIG)
    truth = json.loads((d / "truth.json").read_text())
    assert not any(e["name"] == "jig_misalignment" for e in truth["effects"])
    truth["effects"].append({"name": "jig_misalignment", "params": MOVED})
    (d / "moved.json").write_text(json.dumps(truth))
    simulate_jig(d / "b.csv", "--truth", d / "moved.json", "--seed", "12", *JIG)
    cdm.fit(d / "a.csv", DEVICE_JSON, ["exit_pulley"], calibration_out=d / "cal.json")
    # A calibration missing the effect the device has: cable_offset cannot
    # bend with the cable's exit angle as exit_pulley does.
    cdm.fit(d / "a.csv", DEVICE_JSON, ["cable_offset"], calibration_out=d / "wrong.json")
    return d


def test_a_calibration_holds_on_a_new_session_with_the_jig_moved(sessions):
    r = cdm.check(sessions / "b.csv", sessions / "cal.json")
    assert r["model_check"]["holds"], r["model_check"]["text"]
    assert r["model_check"]["text"].startswith("the calibration holds")
    assert r["effects"] == ["exit_pulley"] and r["jig"]["added"] and r["jig"]["re_estimated"]
    assert r["positions"] == 7 * 7 * 3
    # The jig's placement is found: each parameter within four of its
    # standard errors of the move (the calibration's own error, which the
    # standard errors leave out, is far below them: it holds, above).
    (jig,) = r["jig"]["effects"]
    assert jig["name"] == "jig_misalignment"
    for name, true in MOVED.items():
        p = jig["params"][name]
        assert abs(p["value"] - true) < 4 * p["std"], (name, p, true)
    # The calibration's systematic error on this session is its noise: each
    # position's mean error has the variance of 10 samples' mean plus the
    # jig's own seating error (0.03 mm per axis, the simulator's default),
    # so its RMS over the plate is below twice that floor's.
    floor = math.sqrt(0.03 ** 2 + 0.05 ** 2 / 10)
    for a in "xyz":
        assert r["position_error_mm"][a]["rms"] < 2 * floor, (a, r["position_error_mm"][a])
        # per sample, as the seed's Table 1: the nominal triangulation is worse
        assert r["error_mm"][a]["rms"] <= r["nominal_error_mm"][a]["rms"] + 1e-12
    # ... and as its own accuracy map predicted (the chi-square of the
    # positions' errors against noise, jig and the propagated covariance).
    assert r["predicted"]["available"] and r["predicted"]["as_predicted"], r["predicted"]
    assert r["predicted"]["p_value"] >= 1e-3
    assert r["calibration_fit"]["data"].endswith("a.csv")
    assert set(r["calibration_fit"]["error_mm"]) == {"x", "y", "z"}


def test_a_calibration_that_misses_an_effect_does_not_hold(sessions):
    good = cdm.check(sessions / "b.csv", sessions / "cal.json")
    r = cdm.check(sessions / "b.csv", sessions / "wrong.json")
    assert not r["model_check"]["holds"], r["model_check"]["text"]
    assert r["model_check"]["text"].startswith("the calibration does not hold")
    # The verdict and the numbers beside it agree: its test fails (p < 1e-3).
    assert min(r["model_check"]["chi2_p_value"], r["model_check"]["structure"]["p_value"]) < 1e-3
    assert r["failing"]["count"] > good["failing"]["count"]
    # Its error is beyond what its own covariance allows, too.
    assert not r["predicted"]["as_predicted"] and r["predicted"]["p_value"] < 1e-3
    assert r["position_error_mm"]["x"]["rms"] > good["position_error_mm"]["x"]["rms"]


def test_a_session_that_leaves_the_jig_undetermined_is_inconclusive(sessions, tmp_path):
    """Four positions on one line of one height: the jig's placement takes up
    any error along what they leave free, so no verdict is drawn from them."""
    lines = (sessions / "b.csv").read_text().splitlines()
    points = []
    for line in lines[1:]:
        p = line.split(",")[0]
        if p not in points:
            points.append(p)
    keep = set(points[:4])
    few = tmp_path / "few.csv"
    few.write_text("\n".join([lines[0]] + [l for l in lines[1:] if l.split(",")[0] in keep]) + "\n")
    mc = cdm.check(few, sessions / "cal.json")["model_check"]
    assert not mc["conclusive"] and not mc["holds"], mc
    assert mc["text"].startswith("the check is inconclusive") and mc["jig_undetermined"]
    full = cdm.check(sessions / "b.csv", sessions / "cal.json")["model_check"]
    assert full["conclusive"] and not full["jig_undetermined"]


def test_ignored_columns_are_said(sessions, tmp_path):
    lines = (sessions / "b.csv").read_text().splitlines()
    extra = tmp_path / "extra.csv"
    extra.write_text("\n".join([lines[0] + ",operator"] + [l + ",jd" for l in lines[1:]]) + "\n")
    assert cdm.check(extra, sessions / "cal.json")["data"]["ignored_columns"] == ["operator"]
    r = subprocess.run([os.environ["CDM_CLI"], "calib", "check", os.fspath(extra), "--calibration",
                        os.fspath(sessions / "cal.json"), "--quiet"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "columns ignored" in r.stdout and "operator" in r.stdout, r.stderr


def test_max_error_lists_the_positions_beyond_it(sessions):
    r = cdm.check(sessions / "b.csv", sessions / "wrong.json", max_error_mm=0.05)
    beyond = r["failing"]["beyond_max_error"]
    assert beyond["max_error_mm"] == 0.05
    assert beyond["count"] == len(beyond["positions"]) > 0
    for p in beyond["positions"]:
        assert math.hypot(*p["error_mm"]) > 0.05
        assert set(p) == {"point", "ref", "error_mm"}


def _check(data, calibration, options):
    L = _native.lib()
    out = ctypes.c_void_p()
    rc = L.cdm_check(os.fspath(data).encode(), os.fspath(calibration).encode(),
                     None if options is None else json.dumps(options).encode(), _native.cdm_progress_fn(), None,
                     ctypes.byref(out))
    err = _native.text(L.cdm_thread_error())
    if out.value:
        L.cdm_free_string(out)
    return rc, err


def test_bad_options_and_files_are_named(sessions, tmp_path):
    rc, err = _check(sessions / "b.csv", sessions / "cal.json", {"effects": ["exit_pulley"]})
    assert rc == CDM_ERR_INVALID_ARG and '"effects"' in err and "max_error_mm" in err
    rc, err = _check(sessions / "b.csv", sessions / "cal.json", {"max_error_mm": -1})
    assert rc == CDM_ERR_INVALID_ARG and "max_error_mm" in err
    rc, err = _check(sessions / "b.csv", tmp_path / "none.json", None)
    assert rc == CDM_ERR_IO and "none.json" in err
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "cdm-calibration", "version": 1, "effects": [}')
    rc, err = _check(sessions / "b.csv", bad, None)
    assert rc == CDM_ERR_PARSE and "bad.json:1:" in err
    unknown = json.loads((sessions / "cal.json").read_text())
    unknown["effects"][0]["name"] = "no_such_effect"
    (tmp_path / "unknown.json").write_text(json.dumps(unknown))
    rc, err = _check(sessions / "b.csv", tmp_path / "unknown.json", None)
    assert rc == CDM_ERR_PARSE and "no_such_effect" in err
    # What the calibration's fit says of itself is shown beside the check:
    # an RMS that is no number of mm is refused, not printed.
    for rms, words in [(1e308, "got 1e+308"), (-1, "got -1"), ("0.1", "got a string"), (None, "is missing")]:
        edited = json.loads((sessions / "cal.json").read_text())
        if rms is None:
            del edited["fit"]["error_mm"]["y"]["rms"]
        else:
            edited["fit"]["error_mm"]["y"]["rms"] = rms
        (tmp_path / "edited.json").write_text(json.dumps(edited, indent=1))
        rc, err = _check(sessions / "b.csv", tmp_path / "edited.json", None)
        assert rc == CDM_ERR_PARSE and "edited.json:" in err and "fit.error_mm.y.rms" in err and words in err, err


def cli_check(sessions, *args):
    """`cdm calib check b.csv --calibration cal.json ARGS --quiet`."""
    return subprocess.run([os.environ["CDM_CLI"], "calib", "check", os.fspath(sessions / "b.csv"), "--calibration",
                           os.fspath(sessions / "cal.json"), *map(os.fspath, args), "--quiet"],
                          capture_output=True, text=True, timeout=300)


def test_the_cli_prints_the_verdict_and_writes_the_json(sessions, tmp_path):
    cli = os.environ["CDM_CLI"]
    out = tmp_path / "check.json"
    r = cli_check(sessions, "--json", out)
    assert r.returncode == 0, r.stderr
    assert "Verdict: the calibration holds" in r.stdout and "jig's placement was fitted" in r.stdout
    assert json.loads(out.read_text())["model_check"]["holds"]
    r = subprocess.run([cli, "calib", "check", os.fspath(sessions / "b.csv")], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "--calibration" in r.stderr


def test_the_report_draws_measured_against_predicted(sessions, tmp_path):
    """`cdm calib check --report DIR`: the check's page, from its per-position
    arrays (each placed position's error, the calibration's predicted
    1-sigma and the expected one with noise and jig, and its chi-square)."""
    rep = tmp_path / "report"
    r = cli_check(sessions, "--report", rep)
    assert r.returncode == 0, r.stderr
    check = json.loads((rep / "check.json").read_text())
    assert check["tool"] == "cdm calib check"
    pp = check["predicted"]["per_position"]
    n = len(pp["chi2"])
    assert n == check["positions"] and all(len(pp[k]) == n for k in ("ref_mm", "error_mm", "calibration_sigma_mm",
                                                                      "expected_sigma_mm"))
    # The expected error holds the calibration's own and more (noise, jig).
    assert all(e >= c for pe, pc in zip(pp["expected_sigma_mm"], pp["calibration_sigma_mm"]) for e, c in zip(pe, pc))
    page = (rep / "index.html").read_text()
    assert "Does the calibration hold here?" in page and "Measured against predicted" in page
    assert (rep / "check_predicted.png").stat().st_size > 1000 and (rep / "check_maps.png").stat().st_size > 1000
    # A directory that is not the report's is refused, and nothing is written.
    other = tmp_path / "other"
    other.mkdir()
    (other / "mine.txt").write_text("x")
    r = cli_check(sessions, "--report", other)
    assert r.returncode == 2 and "holds no report" in r.stderr
    assert sorted(p.name for p in other.iterdir()) == ["mine.txt"]
