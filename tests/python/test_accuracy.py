"""The accuracy map through the bindings: cdm_fit's accuracy_map as numpy
arrays (cdm.accuracy_map), the calibration file's covariance and
cdm_calibration_position_covariance, and a covariance that does not fit its
model refused on load. Its coverage against the truth is
tests/unit/calib/test_accuracy.cpp's."""
import json
import math
import os

import numpy as np
import pytest

import cdm
from conftest import simulate_jig

DEVICE_JSON = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples", "device.json")


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    d = tmp_path_factory.mktemp("accuracy")
    simulate_jig(d / "ds.csv", "--device", DEVICE_JSON, "--effects", "exit_pulley,cable_gain", "--effect-seed", "5",
                 "--holes", "7", "--heights", "40,55,70", "--samples", "10")
    r = cdm.fit(d / "ds.csv", DEVICE_JSON, ["exit_pulley", "cable_gain"], calibration_out=d / "cal.json")
    return d, r


def test_the_map_as_arrays_agrees_with_its_summary(fitted):
    _, r = fitted
    m = cdm.accuracy_map(r)
    n = len(m["x"])
    assert n == len(m["levels"]) * m["ny"] * m["nz"] and m["sigma"].shape == (n, 3) and m["cov"].shape == (n, 3, 3)
    assert m["placed"].all() and m["inside"].any() and (~m["inside"]).any()
    # The fixture heights 40, 55, 70 mm, and one level past each end.
    assert len(m["levels"]) == 5 and np.all(np.diff(m["levels"]) > 0)
    assert not m["inside"][: m["ny"] * m["nz"]].any() and not m["inside"][-m["ny"] * m["nz"]:].any()
    s = r["accuracy_map"]["summary"]
    for k, a in enumerate("xyz"):
        assert s["inside"]["sigma_mm"][a]["mean"] == pytest.approx(m["sigma"][m["inside"], k].mean(), rel=1e-12)
        assert s["inside"]["sigma_mm"][a]["max"] == pytest.approx(m["sigma"][m["inside"], k].max(), rel=1e-12)
    # sigma is the covariance's diagonal; the 95 % radius its largest
    # eigenvalue's, scaled by chi-square(3)'s 95 % quantile.
    assert np.allclose(m["sigma"] ** 2, np.diagonal(m["cov"], axis1=1, axis2=2), rtol=1e-12)
    assert np.allclose(m["radius95"] ** 2, 7.814727903251178 * np.linalg.eigvalsh(m["cov"])[:, -1], rtol=1e-9)
    # Extrapolated, the error grows: the worst point outside is past the worst inside.
    assert s["outside"]["radius95_mm"]["max"] > s["inside"]["radius95_mm"]["max"]


def test_the_calibration_carries_the_covariance_the_map_used(fitted):
    d, r = fitted
    m = cdm.accuracy_map(r)
    cal = cdm.Calibration.load(d / "cal.json")
    # exit_pulley and cable_gain do not drift: the map's time does not matter.
    for j in np.flatnonzero(m["inside"])[::37]:
        c = np.array(cal.position_covariance((m["x"][j], m["y"][j], m["z"][j])))
        assert np.allclose(c, m["cov"][j], rtol=1e-9, atol=1e-15), j
    assert json.loads((d / "cal.json").read_text())["fit"]["covariance"]["parameters"][0].startswith("exit_pulley.")


def test_a_calibration_without_or_with_a_wrong_covariance(fitted, tmp_path):
    d, _ = fitted
    cal = json.loads((d / "cal.json").read_text())
    del cal["fit"]["covariance"]
    (tmp_path / "none.json").write_text(json.dumps(cal))
    with pytest.raises(cdm.CdmError) as e:
        cdm.Calibration.load(tmp_path / "none.json").position_covariance((55, 0, 0))
    assert "carries no covariance" in str(e.value)
    good = json.loads((d / "cal.json").read_text())["fit"]["covariance"]
    for bad, words in [({**good, "parameters": ["x"] + good["parameters"][1:]}, "parameter 0"),
                       ({**good, "matrix": good["matrix"][:-1]}, "must be"),
                       ({**good, "matrix": [[-1.0] + row[1:] if i == 0 else row
                                            for i, row in enumerate(good["matrix"])]}, "negative"),
                       ({**good, "matrix": good["matrix"] + [good["matrix"][0]]}, "must be"),
                       # symmetric, positive diagonal, but no covariance: a correlation of 5
                       ({**good, "matrix": [[1.0 if i == k else (5.0 if {i, k} == {0, 1} else 0.0)
                                             for k in range(len(good["matrix"]))]
                                            for i in range(len(good["matrix"]))]}, "not a covariance")]:
        cal["fit"]["covariance"] = bad
        (tmp_path / "bad.json").write_text(json.dumps(cal))
        with pytest.raises(cdm.ParseError) as e:
            cdm.Calibration.load(tmp_path / "bad.json")
        assert "fit.covariance" in str(e.value) and words in str(e.value), str(e.value)


def test_the_fit_prints_the_predicted_error(fitted, tmp_path):
    import subprocess
    d, r = fitted
    p = subprocess.run([os.environ["CDM_CLI"], "calib", "fit", os.fspath(d / "ds.csv"), "--device", DEVICE_JSON,
                        "--effects", "exit_pulley,cable_gain", "--out", os.fspath(tmp_path / "c.json"), "--quiet"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    line = next(x for x in p.stdout.splitlines() if x.startswith("predicted error (1-sigma) over the jig's volume"))
    worst = r["accuracy_map"]["summary"]["inside"]["radius95_mm"]["max"]
    assert f"worst {worst:.4f} mm" in line
    assert math.isfinite(worst) and worst > 0
