"""Geometry-aware user effects from Python (register_effect(geometry=True),
since 1.2): what the callback gets, the checks on a registration, the
cable-sag example (examples/python/cable_sag.py) fitted and streamed through
sim: with its calibration, and a calibration that names a Python effect the
process has not registered."""
import ctypes
import importlib.util
import json
import os
import time

import numpy as np
import pytest

import cdm
from cdm import _native

SRC = os.environ.get("CDM_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
DEVICE = {"a_mm": 150.0, "b_mm": 150.0, "m_mm": 30.0}
C_TRUE = 4e-8  # 1/mm^2: 0.3 mm on a 200 mm horizontal cable


def _load(name, *path):
    spec = importlib.util.spec_from_file_location(name, os.path.join(SRC, *path))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


SAG = _load("cable_sag_example", "examples", "python", "cable_sag.py")
WORN = _load("user_effect_example_geom", "docs", "examples", "user_effect.py")  # its make_dataset


def _calibration(effects):
    return json.dumps({"format": "cdm-calibration", "version": 1, "device": DEVICE, "effects": effects})


def test_registration_refuses_bad_parameter_names_and_units():
    def noop(params, geom, values):
        pass
    cases = [
        (dict(param_names=[""], param_scale=[1]), ValueError, "not an identifier"),
        (dict(param_names=["depth mm"], param_scale=[1]), ValueError, "not an identifier"),
        (dict(param_names=["a", "a"], param_scale=[1, 1]), ValueError, "given twice"),
        (dict(param_names=[3], param_scale=[1]), TypeError, "must be a str"),
        (dict(param_names="ab", param_scale=[1]), TypeError, "list of names"),
        (dict(param_names=["a"], param_scale=[1], units=['m"m']), ValueError, "quote"),
        (dict(param_names=["a"], param_scale=[1], units=["\udcff"]), ValueError, "UTF-8"),
        (dict(param_names=["a"], param_scale=[1], units=["mm", "mm"]), ValueError, "2 values for 1"),
        (dict(param_names=["a"], param_scale=[1], stage="pot"), ValueError, "stage must be"),
    ]
    for kwargs, exc, text in cases:
        with pytest.raises(exc, match=text):
            cdm.register_effect("geom_bad", apply=noop, geometry=True, **kwargs)
    with pytest.raises(ValueError, match="needs geometry=True"):
        cdm.register_effect("geom_bad", ["a"], [1], noop, stage="path")
    assert "geom_bad" not in cdm.effect_names()


def test_callback_gets_the_models_geometry():
    seen = {}

    def probe(params, geom, values):
        seen.update(stage=geom.stage, positions=geom.positions.copy(), t_s=geom.t_s.copy(),
                    anchors=geom.anchors.copy(), holders=geom.holders.copy(), unit=geom.unit.copy(),
                    chord=geom.chord.copy(), values=values.copy())
        return values + params[0]  # returned rather than changed in place

    cdm.register_effect("geom_probe", ["shift_mm"], [0.1], probe, units=["mm"], stage="path", geometry=True)
    try:
        shift = {"a%d_%s" % (i, x): 0.0 for i in range(1, 5) for x in "xyz"}
        shift["a2_y"] = 0.7
        cal = cdm.Calibration.parse(_calibration([{"name": "anchor_position", "params": shift},
                                                  {"name": "geom_probe", "params": {"shift_mm": 0.25}}]))
        p = np.array([50.0, 10.0, -20.0])
        L = np.array(cal.lengths(p))
        cal.close()
    finally:
        cdm.unregister_effect("geom_probe")
    assert seen["stage"] == "path"
    assert seen["positions"].shape == (1, 3) and np.array_equal(seen["positions"][0], p)
    assert seen["t_s"].shape == (1,)
    assert seen["anchors"].shape == seen["holders"].shape == seen["unit"].shape == (1, 4, 3)
    assert seen["chord"].shape == seen["values"].shape == (1, 4)
    sy, sz = np.array([1, 1, -1, -1]), np.array([-1, 1, -1, 1])
    anchors = np.stack([np.zeros(4), 150.0 * sy, 150.0 * sz], axis=1)
    anchors[1, 1] += 0.7  # a2_y: the anchor the fit would move is the one the callback sees
    holders = p + np.stack([np.zeros(4), 15.0 * sy, 15.0 * sz], axis=1)
    assert np.allclose(seen["anchors"][0], anchors, atol=1e-12)
    assert np.allclose(seen["holders"][0], holders, atol=1e-12)
    chord = np.linalg.norm(holders - anchors, axis=1)
    assert np.allclose(seen["chord"][0], chord, atol=1e-12)
    assert np.allclose(seen["unit"][0], (holders - anchors) / chord[:, None], atol=1e-12)
    # Nothing after the path: the readings are the lengths plus the shift.
    assert np.allclose(seen["values"][0], chord, atol=1e-12)
    assert np.allclose(L, chord + 0.25, atol=1e-12)


@pytest.fixture(scope="module")
def sag_fit(tmp_path_factory):
    d = tmp_path_factory.mktemp("sag")
    device = d / "device.json"
    device.write_text(json.dumps(DEVICE))
    truth_path = d / "truth.json"
    truth_path.write_text(_calibration([
        {"name": "cable_offset", "params": {"o1": 0.4, "o2": -0.3, "o3": 0.2, "o4": -0.5}},
        {"name": "cable_sag", "params": {"c_per_mm2": C_TRUE}}]))
    SAG.register()
    truth = cdm.Calibration.load(truth_path)
    data = d / "jig.csv"
    WORN.make_dataset(str(data), truth, np.random.default_rng(7), holes=9, heights=(30, 50, 70), samples=10)
    truth.close()
    cal = d / "cal.json"
    r = cdm.fit(str(data), str(device), ["cable_offset", "cable_sag"], calibration_out=cal)
    yield r, cal, truth_path
    if "cable_sag" in cdm.effect_names():
        cdm.unregister_effect("cable_sag")


def test_sag_example_is_recovered_and_recorded(sag_fit):
    r, cal, _ = sag_fit
    (e,) = [e for e in r["effects"] if e["name"] == "cable_sag"]
    c = e["params"]["c_per_mm2"]
    assert c["unit"] == "1/mm^2"
    # Within 5 standard errors of the truth: the fit's own uncertainty.
    assert abs(c["value"] - C_TRUE) < 5 * c["std"], c
    (rec,) = [e for e in json.load(open(cal))["effects"] if e["name"] == "cable_sag"]
    assert rec["origin"] == "python:cable_sag_example"
    assert len(rec["fingerprint"]) == 16


def _truth_error_rms(uri, calibration, poses=80):
    # The reader thread calls the Python effect a few dozen times per pose:
    # the simulator runs at 200 Hz and the loop waits for each pose. With a
    # calibration, only the poses computed with it count (the first ones may
    # come before set_calibration).
    L = _native.lib()
    err = []
    with cdm.open(uri, calibration=calibration) as dev:
        after = 0
        deadline = time.monotonic() + 30
        while len(err) < poses and time.monotonic() < deadline:
            pose = dev.wait_pose(timeout=2.0, after=after)
            after = pose.host_sequence
            if calibration is not None and not pose.is_compensated:
                continue
            truth = (ctypes.c_double * 3)()
            if L.cdm_sim_truth(dev._handle("cdm_sim_truth"), pose.sequence, truth) == 0:
                err.append(np.array(pose.position) - np.array(truth[:]))
    assert len(err) == poses
    return np.sqrt(np.mean(np.square(err), axis=0)).max()


def test_sag_calibration_streams_through_sim_against_the_truth(sag_fit):
    r, cal, truth_path = sag_fit
    uri = "sim:?truth=%s&noise=0&motion=random&rate=200" % truth_path
    fitted = _truth_error_rms(uri, str(cal))
    floor = _truth_error_rms(uri, str(truth_path))
    nominal = _truth_error_rms(uri, None)
    params = {e["name"]: e["params"] for e in r["effects"]}
    s_o = max(params["cable_offset"][k]["std"] for k in ("o1", "o2", "o3", "o4"))
    s_c = params["cable_sag"]["c_per_mm2"]["std"]
    # The floor: the ADC counts 0.01 mm, a uniform rounding of 0.0029 mm RMS
    # per reading, which reaches x (out of the plane, >= 30 mm) amplified by
    # at most ~3: under 0.01 mm. The fitted calibration adds the fit's
    # uncertainty: 5 standard errors of an offset (x amplification <= 3) and
    # of c (times L^3, L <= 260 mm). Uncorrected, the sag and the offsets
    # are tenths of a millimetre.
    bound = floor + 5 * 3 * s_o + 5 * s_c * 260.0 ** 3
    print("error against the truth, worst axis RMS: nominal %.4f mm, fitted %.4f mm (bound %.4f), truth %.4f mm"
          % (nominal, fitted, bound, floor))
    assert floor < 0.01, floor
    assert fitted < bound, (fitted, bound)
    assert nominal > 10 * fitted, (nominal, fitted)


def test_calibration_names_the_missing_python_effect(sag_fit):
    _, cal, _ = sag_fit
    cdm.unregister_effect("cable_sag")
    try:
        with pytest.raises(cdm.CdmError, match=r'user effect "cable_sag" is not registered.*cable_sag_example'):
            cdm.Calibration.load(cal)
        # Another version of it (a unit changed): the fingerprint differs.
        cdm.register_effect("cable_sag", ["c_per_mm2"], [1e-8], SAG.cable_sag, units=["1/m^2"], stage="path",
                            geometry=True, lower=[0.0], upper=[1e-6])
        with pytest.raises(cdm.CdmError, match="fingerprint"):
            cdm.Calibration.load(cal)
    finally:
        SAG.register()
