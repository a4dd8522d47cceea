"""The diagnosis on effects outside its catalogue.

Each case hides one physical effect that no catalogue entry describes
(hidden_effects.c, loaded by the simulator only: the diagnosis is not told)
in a simulated jig session, and checks what a user would read:
  - the verdict never calls the data explained by stand-ins without naming
    them: the recommended model is either not explained, or its stand-ins are
    listed (recommended.stand_ins) and the words say "with stand-ins";
  - the proposed term (`discovered`) names the physical variable the hidden
    effect depends on.
The session is the seed's plate at 13 x 13 holes, 5 heights, 40 samples
(0.05 mm pot noise, 0.03 mm jig tolerance: the defaults): large enough that
each hidden effect (0.05-0.15 mm of reading) is far above the noise of a
per-position mean (0.05 / sqrt(40) = 0.008 mm), small enough for CI.
"""
import json
import os

import pytest

from conftest import cdm

PLUGIN = os.environ.get("CDM_HIDDEN_PLUGIN", "")

# name: (truth parameters, the variable the proposed term must name,
#        the terms whose shape is the effect's own)
CASES = {
    "sag": ({"hidden_sag": {"c": 1.2e-8}}, "u_z", {"L^3*(1-u_z^2)", "L^2*(1-u_z^2)", "L^3*u_z^2", "L^2*u_z^2"}),
    "side_guide": ({"hidden_side_guide": {"k": 0.15}}, "u_y", {"u_y^2", "L*u_y^2", "L^2*u_y^2", "L^3*u_y^2",
                                                              "L*(1-u_y^2)", "L^2*(1-u_y^2)", "L^3*(1-u_y^2)"}),
    "holder_weight": ({"hidden_holder_weight": {"w": 5e-4}}, "u_z", {"L*u_z", "u_z"}),
    "worn_spot": ({"hidden_worn_spot": {"amplitude": 0.12, "centre": 200.0, "width": 8.0}}, "cable length", None),
}


def truth_file(tmp_path, effects):
    """A calibration JSON holding the hidden truth (nominal device)."""
    base = tmp_path / "nominal.json"
    r = cdm("calib", "simulate", str(tmp_path / "x.csv"), "--holes", "3", "--heights", "30", "--samples", "1",
            "--truth-out", str(base))
    assert r.returncode == 0, r.stderr
    t = json.loads(base.read_text())
    t["effects"] = [{"name": n, "params": p} for n, p in effects.items()]
    path = tmp_path / "truth.json"
    path.write_text(json.dumps(t))
    return path


@pytest.fixture(scope="module", params=sorted(CASES))
def diagnosis(request, tmp_path_factory):
    if not PLUGIN:
        pytest.skip("CDM_HIDDEN_PLUGIN not set (ctest sets it)")
    name = request.param
    effects, _, _ = CASES[name]
    tmp = tmp_path_factory.mktemp(name)
    truth = truth_file(tmp, effects)
    data = tmp / "jig.csv"
    r = cdm("calib", "simulate", str(data), "--plugin", PLUGIN, "--truth", str(truth), "--holes", "13",
            "--samples", "40", "--seed", "7", timeout=300)
    assert r.returncode == 0, r.stderr
    out = tmp / "diag.json"
    r = cdm("calib", "diagnose", str(data), "--json", str(out), "--quiet", timeout=600)
    assert r.returncode == 0, r.stderr
    return name, json.loads(out.read_text())


def test_never_explained_by_unnamed_stand_ins(diagnosis):
    name, d = diagnosis
    rec = d["recommended"]
    words = d["verdict"].split(". Search from")[0]
    if rec["stand_ins"]:
        assert not rec["explained"], name
        # "fits to the noise floor with stand-ins" where the tests pass,
        # "its fitted values include stand-ins" where they do not.
        assert "stand-ins" in words and "explains the data" not in words, words
        assert rec["fits_with_stand_ins"] == ("with stand-ins" in words), words
        for s in rec["stand_ins"]:
            assert s["effect"] in words, (s, words)
    else:
        # No stand-in named: the catalogue must not claim the data.
        assert not rec["explained"], (name, words)
        assert "explains the data" not in words, words


def test_proposed_term_names_the_variable(diagnosis):
    name, d = diagnosis
    _, variable, shapes = CASES[name]
    disc = d["discovered"]
    assert disc is not None, (name, d["verdict"])
    lead = disc["terms"][0]
    assert variable in lead["variable"] or variable in lead["term"], (name, disc["terms"])
    if shapes is not None:
        assert lead["term"] in shapes, (name, disc["terms"])
    # The term, fitted with the model, brings the error toward the floor:
    # its x RMS is no larger than the model it was searched in.
    assert disc["delta_chi2"] > 0
    assert "A hypothesis" in d["verdict"]
