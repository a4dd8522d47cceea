"""Missing sections, NaN / null values, odd grids: notes in the page, never a crash."""
import json
import math
import re

import pytest

from conftest import check_page, check_png, run_report
import _synth


def _run(tmp_path, d, name="d.json", allow_nan=False):
    p = tmp_path / name
    p.write_text(json.dumps(d, allow_nan=allow_nan), encoding="utf-8")
    out = tmp_path / "r"
    r = run_report(p, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    html = check_page(out)
    for png in out.glob("*.png"):
        check_png(png)
    return out, html, r


def test_minimal_diagnosis(tmp_path):
    d = {"tool": "cdm calib diagnose", "model": []}
    out, html, _ = _run(tmp_path, d)
    assert "Notes" in html
    for section in ("positions", "candidates", "fingerprints", "unexplained_structure",
                    "error_mm", "structure", "verdict", "explained"):
        assert f"&quot;{section}&quot;" in html, section
    assert "n/a ± n/a" in html
    assert not list(out.glob("*.png"))


def test_older_file_without_tool_field(tmp_path):
    d = _synth.make_diag(n=5, heights=(40,))
    del d["tool"], d["version"]
    _run(tmp_path, d)


def test_missing_optional_sections(tmp_path):
    d = _synth.make_diag(n=9, heights=(30, 50, 70))
    for k in ("fingerprints", "validation", "ellipsoid_error_mm", "structure", "fit", "params"):
        del d[k]
    del d["positions"]["cable_angle_deg"], d["positions"]["length_residual_mm"]
    out, html, _ = _run(tmp_path, d)
    for k in ("fingerprints", "ellipsoid_error_mm", "structure", "positions.cable_angle_deg",
              "positions.length_residual_mm"):
        assert f"&quot;{k}&quot;" in html, k
    names = {p.name for p in out.glob("*.png")}
    assert "vs_variables.png" in names and "residual_map_h50.png" in names
    assert "vs_cable_length.png" not in names
    assert not any(n.startswith("fingerprint_") for n in names)


def test_nan_and_null_values(tmp_path):
    d = _synth.make_diag(n=9, heights=(30, 50))
    pos = d["positions"]
    pos["residual_mm"][0] = [None, None, None]
    pos["residual_mm"][1][0] = float("nan")
    pos["nominal_residual_mm"][2] = None
    pos["lengths_mm"][3][1] = None
    pos["failing"][4] = None
    pos["height"][5] = None
    d["error_mm"]["x"]["rms"] = None
    d["error_mm"]["y"]["mean"] = float("nan")
    d["chi2_per_dof"] = None
    d["candidates"][0]["bic_change"] = None
    d["fingerprints"]["anchor_position"][0] = [None, 1.0, float("inf")]
    out, html, r = _run(tmp_path, d, allow_nan=True)
    assert "n/a ± " in html and "<td>n/a</td>" in html
    assert re.search(r"\b(nan|inf|None)\b", html, re.I) is None, "raw NaN/None in the page"
    assert "warning" not in r.stderr.lower(), r.stderr


def test_mismatched_lengths(tmp_path):
    d = _synth.make_diag(n=5, heights=(30, 60))
    d["positions"]["residual_mm"] = d["positions"]["residual_mm"][:-3]
    d["positions"]["sigma_mm"] = "oops"
    d["fingerprints"]["anchor_position"] = d["fingerprints"]["anchor_position"][:2]
    d["candidates"].append("not an object")
    out, html, _ = _run(tmp_path, d)
    assert "&quot;positions.residual_mm&quot; has 47 entries" in html
    assert "&quot;positions.sigma_mm&quot; has an unusable shape" in html
    # without a current residual, maps show the nominal one and fingerprints say why not
    assert (out / "residual_map_h30.png").exists()
    assert "no per-position residual" in html


def test_mismatched_fingerprint(tmp_path):
    d = _synth.make_diag(n=5, heights=(30, 60))
    d["fingerprints"]["anchor_position"] = d["fingerprints"]["anchor_position"][:2]
    d["fingerprints"]["jig_misalignment"] = {"not": "a list"}
    out, html, _ = _run(tmp_path, d)
    assert "Fingerprint of anchor_position does not match" in html
    assert "Fingerprint of jig_misalignment does not match" in html
    assert [p.name for p in out.glob("fingerprint_*.png")] == ["fingerprint_1_pot_nonlinearity.png"]


def test_single_height(tmp_path):
    out, html, _ = _run(tmp_path, _synth.make_diag(n=11, heights=(50,)))
    assert sorted(p.name for p in out.glob("residual_map_*.png")) == ["residual_map_h50.png"]
    assert "Only one height" in html
    assert (out / "residual_cut.png").exists()


def test_irregular_grid(tmp_path):
    out, html, _ = _run(tmp_path, _synth.make_diag(irregular=True, npos=60, heights=(35, 65)))
    assert (out / "residual_map_h35.png").exists() and (out / "residual_map_h65.png").exists()
    assert (out / "fingerprint_1_anchor_position.png").exists()


def test_coarse_grid_with_holes(tmp_path):
    d = _synth.make_diag(n=7, pitch=10.0, heights=(30, 40, 50, 60, 70, 80, 90))
    keep = [i for i in range(len(d["positions"]["ref"])) if i % 5 != 2]
    for k, v in list(d["positions"].items()):
        d["positions"][k] = [v[i] for i in keep]
    for k, v in list(d["fingerprints"].items()):
        d["fingerprints"][k] = [v[i] for i in keep]
    out, html, _ = _run(tmp_path, d)
    assert len(list(out.glob("residual_map_*.png"))) == 7


def test_single_position(tmp_path):
    out, html, _ = _run(tmp_path, _synth.make_diag(npos=1, heights=(50,)))
    assert (out / "residual_map_h50.png").exists()


def test_unit_helpers():
    m = _module()
    assert m.page.fmt_mm(0.78331) == "0.7833" and m.page.fmt_mm(None) == "n/a"
    assert m.page.fmt_mm(math.nan) == "n/a" and m.page.fmt_mm(True) == "n/a"
    import numpy as np
    c = (np.arange(25) - 12) * 5.0
    y, z = np.meshgrid(c, c)
    g = m.figures._regular_grid(y.ravel(), z.ravel())
    assert g is not None and len(g[0]) == 25 and len(g[1]) == 25
    rng = np.random.default_rng(0)
    assert m.figures._regular_grid(rng.uniform(-60, 60, 50), rng.uniform(-60, 60, 50)) is None
    assert m.sections.variables._finding_target("length_3") == ("length", 3)
    assert m.sections.variables._finding_target("l2") == ("length", 2)
    assert m.sections.variables._finding_target("cable_angle_4") == ("angle", 4)
    assert m.sections.variables._finding_target("distance_from_centre") == ("radius", None)
    assert m.sections.variables._finding_target("height") == ("height", None)


def test_nominal_run_compares_with_ellipsoid(tmp_path):
    """With the nominal model current, the maps' second column is the seed's ellipsoid."""
    out, html, _ = _run(tmp_path, _synth.nominal_run(n=7, heights=(30, 70)))
    assert "right the seed&#x27;s ellipsoid (the baseline to beat)" in html
    assert "solid nominal (current), dashed seed&#x27;s ellipsoid" in html
    assert "not explained" in html


def _module():
    from conftest import report_package
    return report_package()


def test_findings_routed_to_their_panels():
    """Findings as `cdm calib diagnose` words them land on the right panel."""
    m = _module()
    f = [{"variable": "cable length", "kind": "periodic", "axis": "length", "period_mm": 12.5,
          "text": "the cable-length residual repeats every 12.50 mm"},
         {"variable": "l2", "kind": "trend", "axis": "x", "period_mm": None, "text": "x vs l2"},
         {"variable": "angle of cable 3", "kind": "trend", "axis": "z", "text": "z vs angle 3"},
         {"variable": "distance from centre", "kind": "trend", "axis": "y", "text": "y vs r"},
         {"variable": "height", "kind": "trend", "axis": "x", "text": "x vs h"},
         {"variable": "length_4", "kind": "periodic", "axis": "l4", "period_mm": 7.0,
          "text": "ripple on cable 4"},
         {"variable": "temperature", "kind": "trend", "axis": "x", "text": "unplaceable"}]
    pos, length, periods = m.sections.variables._route_findings(f)
    assert pos == {("length", 0): ["x vs l2"], ("angle", 2): ["z vs angle 3"],
                   ("radius", 1): ["y vs r"], ("height", 0): ["x vs h"]}
    assert length == {None: ["the cable-length residual repeats every 12.50 mm"],
                      4: ["ripple on cable 4"]}
    assert periods == [(None, 12.5), (4, 7.0)]


def test_validation_null(tmp_path):
    d = _synth.make_diag(n=5, heights=(40,))
    d["validation"] = None  # what the tool writes for the nominal model or one height
    out, html, _ = _run(tmp_path, d)
    assert "No cross-validation in the diagnosis" in html


def test_outlier_does_not_flatten_the_colour_scale(tmp_path):
    import numpy as np
    m = _module()
    rng = np.random.default_rng(3)
    v = rng.normal(0, 0.05, 625)
    barrel = -np.linspace(0, 2, 625)
    assert not m.figures._symnorm(barrel).clipped and m.figures._symnorm(barrel).vmax == 2.0
    v[7] = 50.0  # one wild position (e.g. a mis-seated pin)
    n = m.figures._symnorm(v)
    assert n.clipped and n.vmax < 1.0
    d = _synth.make_diag(n=9, heights=(40, 60))
    d["positions"]["residual_mm"][7] = [50.0, -50.0, 50.0]
    _run(tmp_path, d)


def _imported():
    """The report package as the tool imports it, so that it may draw in worker processes."""
    return _module()


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_a_failing_figure_is_a_note(tmp_path, monkeypatch, capsys, jobs):
    """A figure whose drawing raises (in this process or in a worker) leaves a note in its
    place; the other figures and the page are written."""
    m = _imported()
    monkeypatch.setenv("CDM_REPORT_JOBS", jobs)
    assert m.drawing._workers(14) == int(jobs)  # "2": really drawn in worker processes

    def broken(*a, **k):
        raise RuntimeError("drawing failed on purpose")
    monkeypatch.setattr(m.sections.variables, "_dots", broken)  # used by the two residual-versus-variable figures
    out = tmp_path / "r"
    m.write_report([_synth.make_diag(n=5, heights=(40, 60))], str(out))
    html = check_page(out)
    for name in ("vs_cable_length.png", "vs_variables.png"):
        assert f"The figure {name} could not be drawn (RuntimeError: drawing failed on purpose)" in html
        assert not (out / name).exists()
    assert (out / "residual_map_h40.png").exists() and (out / "residual_cut.png").exists()
    assert "drawing failed on purpose" in capsys.readouterr().err


def test_page_is_the_same_drawn_in_one_or_two_processes(tmp_path, monkeypatch):
    m = _imported()
    d = _synth.make_diag(n=5, heights=(40, 60))
    pages = []
    for jobs in ("1", "2"):
        monkeypatch.setenv("CDM_REPORT_JOBS", jobs)
        out = tmp_path / jobs
        m.write_report([_synth.nominal_run(n=5, heights=(40, 60)), d], str(out))
        pages.append((check_page(out), sorted(p.name for p in out.glob("*.png"))))
    assert pages[0] == pages[1]


def test_redrawn_figures_are_the_figures_drawn_anew(tmp_path, monkeypatch):
    """The residual maps after the first height and the fingerprints after the first
    are drawn into the process's last figure of their layout (figures._FRAMES); they
    must be pixel for pixel the figures drawn from nothing, whatever was marked or
    scaled in the figure before (here: failing crosses at some heights only, a
    fingerprint with an outlier so that its colour scale is clipped)."""
    import numpy as np
    m = _imported()
    monkeypatch.setenv("CDM_REPORT_JOBS", "1")
    d = _synth.make_diag(n=9, heights=(30, 40, 50, 60))
    pos = d["positions"]
    h = np.array(pos["height"])
    pos["failing"] = [bool(f) and hh in (40.0, 60.0) for f, hh in zip(pos["failing"], h)]
    pos["failing"][int(np.flatnonzero(h == 50.0)[3])] = True  # one cross only
    fps = d["fingerprints"]
    fps["second"] = (np.array(next(iter(fps.values()))) * -3.0).tolist()
    fps["third"] = (np.array(next(iter(fps.values()))) * 0.5).tolist()
    fps["third"][5] = [40.0, 0.0, 0.0]
    assert len(fps) >= 3
    m.write_report([d], str(tmp_path / "kept"))

    class Forgetful(dict):  # keeps no figure: every one drawn anew
        def __setitem__(self, key, value):
            pass
    monkeypatch.setattr(m.figures, "_FRAMES", Forgetful())
    m.write_report([d], str(tmp_path / "anew"))

    import matplotlib.image as mpimg
    names = sorted(p.name for p in (tmp_path / "anew").glob("*.png"))
    assert sum(n.startswith("residual_map_") for n in names) == 4
    assert sum(n.startswith("fingerprint_") for n in names) >= 3
    for name in names:
        a = mpimg.imread(tmp_path / "kept" / name)
        b = mpimg.imread(tmp_path / "anew" / name)
        assert a.shape == b.shape and (a == b).all(), name


def test_a_group_of_figures_is_drawn_by_few_processes():
    m = _imported()

    def fig(name, weight, group=None):
        return m.page._Figure(name, None, "", "", weight, group, 2 if group else 0)
    figures = ([fig(f"map{i}", 2, "maps") for i in range(5)]
               + [fig("a", 7), fig("b", 3), fig("c", 2), fig("d", 1)])
    two = m.drawing._tasks(figures, 2)
    assert sorted(i for t in two for i in t) == list(range(len(figures)))
    assert [0, 1, 2, 3, 4] in two  # the maps (10 + 2 to build, of 25) in one process of two
    four = m.drawing._tasks(figures, 4)
    assert sorted(i for t in four for i in t) == list(range(len(figures)))
    assert [t for t in four if 0 in t][0] != [0, 1, 2, 3, 4]  # split over two of four
    assert four[0] == [0, 1, 2] and four[1] == [5]  # heaviest first
