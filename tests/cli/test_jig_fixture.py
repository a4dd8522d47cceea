"""The height fixture's per-height x offsets (docs/calibration.md, "The jig as
it is"): a trend over the heights that the
device's parameters can take is not the fixture's, and a real spacer error
still is."""
import json
import math

from conftest import cdm

SMALL = ["--holes", "13", "--pitch-mm", "10", "--samples", "40"]


def diagnose(tmp_path, name, sim_args, diag_args):
    csv, out = tmp_path / (name + ".csv"), tmp_path / (name + ".json")
    r = cdm("calib", "simulate", str(csv), *SMALL, *sim_args)
    assert r.returncode == 0, r.stderr
    r = cdm("calib", "diagnose", str(csv), "--json", str(out), *diag_args, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(out.read_text())


def test_a_trend_the_device_can_take_is_not_the_fixture(tmp_path):
    # No fixture error simulated. With a weak prior on the offsets the fit
    # ran along the valley between them and holder_geometry + cable_stretch:
    # one height at the 0.15 mm cap, chi2/dof 1.90, "does not explain"; and
    # the per-height means named "the height fixture's spacers" (p 7e-54).
    effects = "holder_geometry,exit_pulley,cable_stretch"
    d = diagnose(tmp_path, "trend", ["--effects", effects, "--effect-seed", "25", "--seed", "181"],
                 ["--effects", effects, "--no-search", "--no-candidates"])
    # The true model: chi2/dof within 5 standard deviations of 1 for its
    # degrees of freedom (sd sqrt(2/dof), the chi-square's own spread).
    dof = 4 * d["data"]["positions"] - 20
    assert abs(d["chi2_per_dof"] - 1) < 5 * math.sqrt(2 / dof), d["chi2_per_dof"]
    assert d["explained"], d["verdict"]
    fx = d["jig"]["fixture"]
    assert fx["p_value"]["x"] >= 1e-3 and "lr_chi2_x" in fx, fx
    assert "the height fixture's spacers" not in d["verdict"]


def test_a_real_spacer_error_is_still_the_fixture(tmp_path):
    d = diagnose(tmp_path, "spacers", ["--effects", "exit_pulley", "--effect-seed", "15", "--seed", "162",
                                       "--jig-fixture-mm", "0.04"], [])
    fx = d["jig"]["fixture"]
    assert fx["p_value"]["x"] < 1e-3, fx
    assert "the height fixture's spacers" in d["verdict"]
    assert d["recommended"]["effects"] == ["exit_pulley"] and d["recommended"]["explained"], d["recommended"]
