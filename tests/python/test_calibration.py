"""Calibrations, the diagnosis and user effects through the Python binding, on a
small simulated jig dataset with a hidden exit-pulley effect (made by `cdm calib
simulate`, the CLI ctest points CDM_CLI at)."""
import json
import os

import numpy as np
import pytest

import cdm
from conftest import simulate_jig

DEVICE_JSON = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples", "device.json")


@pytest.fixture(scope="module")
def jig(tmp_path_factory):
    d = tmp_path_factory.mktemp("jig")
    simulate_jig(d / "ds.csv", "--effects", "exit_pulley", "--effect-seed", "1", "--truth-out", d / "truth.json",
                 "--holes", "3", "--heights", "40,60", "--samples", "5")
    return d


def test_calibration_round_trip(jig):
    with cdm.Calibration.load(jig / "truth.json") as cal:
        assert "exit_pulley" in cal.effects
        for p in [(50.0, 0.0, 0.0), (40.0, -10.0, 12.0), (65.0, 20.0, -15.0)]:
            lengths = cal.lengths(p)
            assert all(150 < l < 260 for l in lengths), lengths
            # The forward kinematics inverts the model: back to p, to the solver's tolerance.
            assert cal.position(lengths) == pytest.approx(p, abs=1e-4)
        with pytest.raises(ValueError, match="4 numbers"):
            cal.position([1, 2, 3])
        with pytest.raises(ValueError, match="finite"):
            cal.lengths([50, float("nan"), 0])
    with pytest.raises(cdm.CdmError) as e:
        cal.position([200, 200, 200, 200])
    assert e.value.code == cdm.CDM_ERR_INVALID_ARG and "closed" in str(e.value)


def test_calibration_parse_and_errors_name_file_and_line(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{\n  "device": {"a_mm": 150,\n')
    with pytest.raises(cdm.CdmError) as e:
        cdm.Calibration.load(bad)
    assert e.value.code == cdm.CDM_ERR_PARSE and str(bad) in e.value.message
    assert ":3" in e.value.detail or ":2" in e.value.detail, e.value.detail  # a line number
    with pytest.raises(cdm.CdmError) as e:
        cdm.Calibration.load(tmp_path / "missing.json")
    assert "missing.json" in e.value.message
    with pytest.raises(cdm.CdmError) as e:
        cdm.Calibration.parse("[1, 2")
    assert e.value.code == cdm.CDM_ERR_PARSE


def test_set_calibration_compensates_poses(jig):
    cal = cdm.Calibration.load(jig / "truth.json")
    with cdm.open("sim:?motion=still") as dev:
        dev.wait_pose(1.0)
        dev.set_calibration(cal)
        cal.close()  # the library keeps its own copy
        for _ in range(50):
            p = dev.wait_pose(1.0)
            if p.is_compensated:
                break
        assert p.is_compensated
        dev.set_calibration(None)
        for _ in range(50):
            p = dev.wait_pose(1.0)
            if not p.is_compensated:
                break
        assert not p.is_compensated


def test_diagnose_returns_the_json_with_arrays_and_reports_progress(jig):
    stages = []
    r = cdm.diagnose(jig / "ds.csv", DEVICE_JSON, progress=lambda s, f: stages.append((s, f)))
    assert isinstance(r, dict) and "verdict" in r and "candidates" in r
    pos = r["positions"]
    assert isinstance(pos["ref"], np.ndarray) and pos["ref"].shape == (18, 3)
    assert isinstance(pos["residual_mm"], np.ndarray) and pos["residual_mm"].shape[0] == 18
    assert isinstance(pos["failing"], list)  # booleans stay booleans
    assert stages and all(0.0 <= f <= 1.0 for _, f in stages) and all(isinstance(s, str) for s, _ in stages)
    # The hidden effect is the one the diagnosis should rank first.
    assert json.dumps(r["candidates"]).find("exit_pulley") >= 0


def test_diagnose_options_errors_and_cancel(jig):
    with pytest.raises(cdm.CdmError) as e:
        cdm.diagnose(jig / "nope.csv", DEVICE_JSON)
    assert "nope.csv" in e.value.message
    with pytest.raises(cdm.CdmError) as e:
        cdm.diagnose(jig / "ds.csv", DEVICE_JSON, effects=["no_such_effect"])
    assert "no_such_effect" in e.value.message

    class Stop(Exception):
        pass

    def progress(stage, fraction):
        raise Stop(stage)

    with pytest.raises(Stop):  # an exception in the callback cancels and comes back out
        cdm.diagnose(jig / "ds.csv", DEVICE_JSON, progress=progress)
    with pytest.raises(cdm.CdmError):  # a truthy return cancels
        cdm.diagnose(jig / "ds.csv", DEVICE_JSON, progress=lambda s, f: True)


def test_user_effect_registration_and_use(jig):
    calls = []

    def apply(params, position, readings):
        calls.append(1)
        readings[:] = np.asarray(readings) + params[0]  # a common length offset, mm

    names_before = cdm.effect_names()
    cdm.register_effect("py_common_offset", ["offset_mm"], [0.1], apply, doc="test: common offset")
    try:
        assert cdm.effect_names() == names_before + ["py_common_offset"]
        with pytest.raises(ValueError, match="already registered"):
            cdm.register_effect("py_common_offset", ["d"], [0.1], apply)
        r = cdm.diagnose(jig / "ds.csv", DEVICE_JSON, effects=["py_common_offset"])
        assert calls, "the Python effect was never applied"
        assert "py_common_offset" in json.dumps(r["model"]) or "py_common_offset" in json.dumps(r["params"])
    finally:
        cdm.unregister_effect("py_common_offset")
    assert cdm.effect_names() == names_before
    with pytest.raises(cdm.CdmError) as e:
        cdm.register_effect("exit_pulley", ["x"], [1.0], apply)  # a built-in's name
    assert e.value.code == cdm.CDM_ERR_INVALID_ARG
    with pytest.raises(ValueError):
        cdm.register_effect("Bad-Name", ["x"], [1.0], apply)


def test_user_effect_exception_fails_the_diagnosis(jig):
    def apply(params, position, readings):
        raise RuntimeError("boom in apply")

    cdm.register_effect("py_broken", ["x"], [1.0], apply)
    try:
        with pytest.raises(cdm.CdmError) as e:
            cdm.diagnose(jig / "ds.csv", DEVICE_JSON, effects=["py_broken"])
        assert isinstance(e.value.__cause__, RuntimeError) and "py_broken" in str(e.value)
    finally:
        cdm.unregister_effect("py_broken")
