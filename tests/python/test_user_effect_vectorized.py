"""register_effect(vectorized=True): the worked example's effect
(docs/examples/user_effect.py) working on arrays recovers the same parameters
as the same effect called per position."""
import importlib.util
import json
import math
import os

import numpy as np
import pytest

import cdm
from cdm import effects as _effects

SRC = os.environ.get("CDM_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
DEVICE = {"a_mm": 150.0, "b_mm": 150.0, "m_mm": 30.0}
NAMES = ["depth_mm", "centre_mm", "width_mm"]


def _example():
    spec = importlib.util.spec_from_file_location("user_effect_example",
                                                  os.path.join(SRC, "docs", "examples", "user_effect.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


EXAMPLE = _example()


def per_position(params, position, readings):
    # The example's effect, one position at a time, in plain Python.
    depth, centre, width = params
    for i in range(4):
        u = (readings[i] - centre) / width
        readings[i] += depth * math.exp(-u * u)


def _register(name, fn, vectorized):
    cdm.register_effect(name, NAMES, [0.1, 10.0, 2.0], fn, lower=[-5.0, 50.0, 1.0], upper=[5.0, 400.0, 50.0],
                        initial=[0.0, 178.0, 5.0], vectorized=vectorized)


@pytest.fixture(scope="module")
def jig(tmp_path_factory):
    d = tmp_path_factory.mktemp("vecjig")
    device = d / "device.json"
    device.write_text(json.dumps(DEVICE))
    # The truth evaluated through the vectorised effect one position at a
    # time (Calibration.lengths: apply_batch with n = 1).
    _register("worn_spot_truth", EXAMPLE.worn_spot, True)
    truth = cdm.Calibration.parse(json.dumps({
        "format": "cdm-calibration", "version": 1, "device": DEVICE,
        "effects": [{"name": "worn_spot_truth", "params": EXAMPLE.TRUTH}]}))
    data = d / "jig.csv"
    # A smaller plate than the example's (7 x 7 holes on 3 heights, 147
    # positions) keeps the per-position fit to a few seconds.
    EXAMPLE.make_dataset(str(data), truth, np.random.default_rng(5), holes=7, heights=(30, 50, 70), samples=10)
    del truth
    cdm.unregister_effect("worn_spot_truth")
    yield str(data), str(device)


def _params(r, name):
    (e,) = [e for e in r["effects"] if e["name"] == name]
    return e["params"]


def test_vectorized_fit_equals_per_position(jig):
    data, device = jig
    _register("worn_spot_pp", per_position, False)
    _register("worn_spot_vec", EXAMPLE.worn_spot, True)
    try:
        rp = cdm.fit(data, device, ["worn_spot_pp"])
        rv = cdm.fit(data, device, ["worn_spot_vec"])
    finally:
        cdm.unregister_effect("worn_spot_pp")
        cdm.unregister_effect("worn_spot_vec")
    pp, pv = _params(rp, "worn_spot_pp"), _params(rv, "worn_spot_vec")
    for k in NAMES:
        # math.exp per reading against numpy's exp over arrays: the same
        # value to an ulp or so (~1e-16 relative), which moves a fitted
        # parameter by far less than 1e-3 of its standard error.
        assert abs(pp[k]["value"] - pv[k]["value"]) <= 1e-3 * pp[k]["std"], (k, pp[k], pv[k])
        assert abs(pp[k]["std"] - pv[k]["std"]) <= 1e-3 * pp[k]["std"], (k, pp[k], pv[k])
        # and the truth back, within 5 standard errors (the fit's own uncertainty)
        assert abs(pv[k]["value"] - EXAMPLE.TRUTH[k]) < 5 * pv[k]["std"], (k, pv[k])


def test_vectorized_may_return_the_readings(jig):
    data, device = jig

    def returns(params, positions, readings):
        depth, centre, width = params
        u = (readings - centre) / width
        return readings + depth * np.exp(-u * u)

    _register("worn_spot_ret", returns, True)
    try:
        r = cdm.fit(data, device, ["worn_spot_ret"])
    finally:
        cdm.unregister_effect("worn_spot_ret")
    p = _params(r, "worn_spot_ret")
    assert all(abs(p[k]["value"] - EXAMPLE.TRUTH[k]) < 5 * p[k]["std"] for k in NAMES), p


def test_vectorized_failure_fails_the_fit(jig):
    data, device = jig

    def wrong_shape(params, positions, readings):
        return readings[:, :3]

    _register("worn_spot_bad", wrong_shape, True)
    try:
        with pytest.raises(cdm.CdmError) as e:
            cdm.fit(data, device, ["worn_spot_bad"])
    finally:
        cdm.unregister_effect("worn_spot_bad")
    assert "worn_spot_bad" in str(e.value)
    assert "expected" in str(e.value.__cause__)


def test_vectorized_needs_numpy(monkeypatch):
    monkeypatch.setattr(_effects, "_np", None)
    with pytest.raises(ImportError, match="numpy"):
        _register("worn_spot_nonp", EXAMPLE.worn_spot, True)
