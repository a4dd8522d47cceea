"""cdm_fit (experimental, since 1.1): the calibration fit without the
diagnosis. Same fitted parameters as cdm_diagnose's, without its candidates."""
import ctypes
import json
import os
import time

import pytest

import cdm
from cdm import _native
from conftest import simulate_jig

DEVICE_JSON = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples", "device.json")
CDM_ERR_INVALID_ARG = -1


@pytest.fixture(scope="module")
def jig(tmp_path_factory):
    d = tmp_path_factory.mktemp("fitjig")
    simulate_jig(d / "ds.csv", "--effects", "exit_pulley", "--effect-seed", "1", "--holes", "5", "--heights", "40,60",
                 "--samples", "5")
    return d


def _fit(data, options):
    """cdm_fit through the bindings' prototype, options passed verbatim (the
    refusals below are of options cdm.fit() would never build)."""
    L = _native.lib()
    out = ctypes.c_void_p()
    rc = L.cdm_fit(os.fspath(data).encode(), DEVICE_JSON.encode(),
                   None if options is None else json.dumps(options).encode(), _native.cdm_progress_fn(), None,
                   ctypes.byref(out))
    r = None
    if out.value:
        r = json.loads(ctypes.string_at(out.value).decode())
        L.cdm_free_string(out)
    return rc, r


def test_fit_from_python_writes_the_calibration(jig, tmp_path):
    r = cdm.fit(jig / "ds.csv", DEVICE_JSON, ["exit_pulley"], calibration_out=tmp_path / "c.json")
    assert [e["name"] for e in r["effects"]] == ["exit_pulley"] and r["fit"]["converged"]
    assert json.loads((tmp_path / "c.json").read_text())["effects"][0]["name"] == "exit_pulley"


def test_fit_gives_the_diagnosis_parameters_without_the_candidates(jig, tmp_path):
    t0 = time.perf_counter()
    rc, r = _fit(jig / "ds.csv", {"effects": ["exit_pulley"], "calibration_out": str(tmp_path / "c.json")})
    t_fit = time.perf_counter() - t0
    assert rc == 0, r
    t0 = time.perf_counter()
    d = cdm.diagnose(jig / "ds.csv", DEVICE_JSON, effects=["exit_pulley"])
    t_diag = time.perf_counter() - t0
    print(f"cdm_fit {t_fit:.3f} s, cdm_diagnose {t_diag:.3f} s, ratio {t_diag / t_fit:.1f}")
    assert [e["name"] for e in r["effects"]] == ["exit_pulley"]
    # Both run fit_calibration() on the same data: deterministic, so equal to
    # rounding (the JSON round trip keeps 17 digits).
    for name, p in r["effects"][0]["params"].items():
        assert p["value"] == pytest.approx(d["params"]["exit_pulley"][name]["value"], rel=1e-12, abs=1e-15)
        assert p["std"] == pytest.approx(d["params"]["exit_pulley"][name]["std"], rel=1e-12, abs=1e-15)
    assert r["error_mm"]["x"]["rms"] == pytest.approx(d["error_mm"]["x"]["rms"], rel=1e-12)
    assert r["fit"]["converged"] and r["fit"]["dof"] > 0
    assert "candidates" not in r and "model_review" not in r
    assert json.loads((tmp_path / "c.json").read_text())["effects"][0]["name"] == "exit_pulley"


def test_fit_requires_effects(jig):
    for opts in (None, {}, {"effects": []}):
        rc, r = _fit(jig / "ds.csv", opts)
        assert rc == CDM_ERR_INVALID_ARG and r is None
    assert _fit(jig / "ds.csv", {"effects": ["exit_pulley"], "candidates": True})[0] == CDM_ERR_INVALID_ARG


def _misplaced(src, dst, shifts):
    """The jig CSV with the references of some points moved (a wrong hole,
    a mis-seated probe): shifts = {point: (dy, dz)} in mm."""
    with open(src) as f, open(dst, "w") as g:
        g.write(f.readline())
        for line in f:
            v = line.rstrip("\n").split(",")
            if int(v[0]) in shifts:
                dy, dz = shifts[int(v[0])]
                v[2] = f"{float(v[2]) + dy:.4f}"
                v[3] = f"{float(v[3]) + dz:.4f}"
            g.write(",".join(v) + "\n")


def test_fit_sets_misplaced_positions_aside(tmp_path):
    """Three references moved by 1 mm (20 times the jig's 0.03 mm and the
    noise of a position mean): the fit names exactly those three, fits
    without them, and its jig tolerance is the clean file's to its sampling
    error (5 %, as the diagnosis' test); kept, they inflate it."""
    clean = simulate_jig(tmp_path / "clean.csv", "--effects", "exit_pulley", "--effect-seed", "1", "--holes", "9",
                         "--heights", "30,50,70", "--samples", "5")
    bad = tmp_path / "bad.csv"
    shifts = {20: (1.0, 0.0), 100: (0.0, -1.0), 190: (0.7, 0.7)}
    _misplaced(clean, bad, shifts)
    r0 = cdm.fit(clean, DEVICE_JSON, ["exit_pulley"])
    r1 = cdm.fit(bad, DEVICE_JSON, ["exit_pulley"], calibration_out=tmp_path / "c1.json")
    r2 = cdm.fit(bad, DEVICE_JSON, ["exit_pulley"], outliers=False, calibration_out=tmp_path / "c2.json")
    assert r0["outliers"]["count"] == 0 and r0["outliers"]["positions_read"] == 243
    assert sorted(x["point"] for x in r1["outliers"]["set_aside"]) == sorted(shifts)
    assert r2["outliers"]["count"] == 0 and not r2["outliers"]["enabled"]
    # The calibration file alone says which positions its fit left out (and
    # that none was screened out when the screen was off).
    c1 = json.loads((tmp_path / "c1.json").read_text())["fit"]
    c2 = json.loads((tmp_path / "c2.json").read_text())["fit"]
    assert c1["data"] == str(bad) and c1["set_aside"]["outliers_screened"]
    assert sorted(x["point"] for x in c1["set_aside"]["positions"]) == sorted(shifts)
    assert c2["set_aside"]["positions"] == [] and not c2["set_aside"]["outliers_screened"]
    assert c1["set_aside"]["glitch_samples"] == r1["glitches"]["count"]
    for a in (1, 2):
        j0, j1, j2 = (r["jig_tolerance_mm"][a] for r in (r0, r1, r2))
        assert abs(j1 - j0) <= 0.05 * j0, (a, j0, j1)
        assert j2 > 1.1 * j0, (a, j0, j2)


def heights_jig(tmp_path, edit):
    """The 9 x 9 plate at 30, 50 and 70 mm (exit_pulley hidden, 5 samples)
    rewritten row by row: edit(v) gets a row's fields (point, x_ref, y_ref,
    z_ref, l1..l4, as text) and returns them, changed or not, or None to
    drop the row."""
    clean = simulate_jig(tmp_path / "clean.csv", "--effects", "exit_pulley", "--effect-seed", "1", "--holes", "9",
                         "--heights", "30,50,70", "--samples", "5")
    out = tmp_path / "edited.csv"
    with open(clean) as f, open(out, "w") as g:
        g.write(f.readline())
        for line in f:
            v = edit(line.rstrip("\n").split(","))
            if v is not None:
                g.write(",".join(v) + "\n")
    return out


def raised(points):
    """An edit that raises the given points' x_ref by the mm given."""
    def edit(v):
        dx = points.get(int(v[0]), 0.0)
        if dx:
            v[1] = f"{float(v[1]) + dx:.4f}"
        return v
    return edit


def diagnosed_heights(path):
    return cdm.diagnose(path, DEVICE_JSON, effects=["exit_pulley"], candidates=False, validation=False)


def test_a_reference_off_its_height_is_judged_not_made_a_height(tmp_path):
    """One reference 1 mm above its fixture height (a probe seated high) and
    one 4 micrometres off (a value typed from a gauge): neither is a height of
    its own (each would have had its own fixture offset, absorbing the 1 mm,
    and no neighbours). The 1 mm one is set aside, as one moved in y or z is;
    the other is listed and kept. Made heights of their own, they would leave
    the diagnosis of this file at "does not explain the data" with nothing set
    aside."""
    bad = heights_jig(tmp_path, raised({100: 1.0, 20: 0.004}))
    r = cdm.fit(bad, DEVICE_JSON, ["exit_pulley"])
    assert [x["point"] for x in r["outliers"]["set_aside"]] == [100], r["outliers"]
    d = diagnosed_heights(bad)
    assert d["data"]["heights"] == [30.0, 50.0, 70.0] and d["data"]["off_height_points"] == [20], d["data"]
    assert [x["point"] for x in d["data"]["outliers"]["set_aside"]] == [100]
    assert d["explained"], d["verdict"]


def test_two_references_at_the_same_wrong_height_are_not_a_height(tmp_path):
    """Two references 1 mm above their fixture height with the same x_ref (a
    spacer left in for two holes): a group of two positions is not a
    fixture height (that would give it an offset of its own, absorbing the
    error, and no neighbours on the plate; the diagnosis said "does not
    explain the data" and named a 0.5 mm spacer). Their holes are the ones
    missing at 50 mm: both are off their height, grouped with it, and set
    aside like one such reference."""
    d = diagnosed_heights(heights_jig(tmp_path, raised({100: 1.0, 112: 1.0})))  # both at 50 mm
    # (off_height_points lists those of the data the statistics are on: the
    # two are set aside, so none is left.)
    assert d["data"]["heights"] == [30.0, 50.0, 70.0] and d["data"]["off_height_points"] == [], d["data"]
    assert [x["point"] for x in d["data"]["outliers"]["set_aside"]] == [100, 112], d["data"]["outliers"]
    assert d["explained"], d["verdict"]


def test_a_height_recorded_part_way_is_still_a_height(tmp_path):
    """A recording that stopped 15 positions into its last height (of 81):
    those 15 share their x_ref and are a fixture height of their own (their
    own offset, neighbours among themselves), not references off the height
    20 mm below. 15 is under a quarter of a full height, but they measure
    holes the height below has."""
    d = diagnosed_heights(heights_jig(tmp_path, lambda v: v if int(v[0]) < 2 * 81 + 15 else None))
    assert d["data"]["heights"] == [30.0, 50.0, 70.0] and d["data"]["off_height_points"] == [], d["data"]
    assert d["data"]["positions"] == 177, d["data"]


def test_small_heights_on_the_same_holes_are_heights(tmp_path):
    """A jig that measures 9 x 9 holes at 50 mm but only the middle 3 x 3 at
    30 and 70 mm (a workspace that narrows): the small heights measure holes
    the full one has, so they are heights with their own fixture offsets,
    not references moved off 50 mm (9 positions are under a quarter of 81)."""
    def middle(v):
        keep = abs(float(v[1]) - 50.0) < 1e-9 or (abs(float(v[2])) <= 5.0001 and abs(float(v[3])) <= 5.0001)
        return v if keep else None
    d = diagnosed_heights(heights_jig(tmp_path, middle))
    assert d["data"]["positions"] == 81 + 2 * 9, d["data"]
    assert d["data"]["heights"] == [30.0, 50.0, 70.0] and d["data"]["off_height_points"] == [], d["data"]


def test_fit_says_when_its_effects_do_not_explain_the_data(jig, tmp_path):
    """A fit of the wrong effects converges too: cdm_fit's model_check says,
    by the diagnosis's own two tests, that they do not explain the data (the
    jig hides an exit pulley of a few mm: cable offsets leave chi2/dof over
    100), and that the right one does."""
    right = cdm.fit(jig / "ds.csv", DEVICE_JSON, ["exit_pulley"], calibration_out=tmp_path / "a.json")
    wrong = cdm.fit(jig / "ds.csv", DEVICE_JSON, ["cable_offset"], calibration_out=tmp_path / "b.json")
    assert wrong["fit"]["converged"]
    assert right["model_check"]["explained"] is True
    assert right["model_check"]["chi2_p_value"] >= 1e-3 and right["model_check"]["structure"]["p_value"] >= 1e-3
    w = wrong["model_check"]
    assert w["explained"] is False and w["chi2_per_dof"] > 10
    assert "do not explain the data" in w["text"] and "cdm calib diagnose" in w["text"]
