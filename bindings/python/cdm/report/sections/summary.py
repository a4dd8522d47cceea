"""Section 1: the verdict, the error table, the facts of the run, the fitted
parameters, the validation and the bar chart of the error per axis."""
from __future__ import annotations

from typing import Any, Dict, TYPE_CHECKING

if TYPE_CHECKING:
    from ..page import Page

from ..loading import Diag

import numpy as np
import matplotlib.pyplot as plt

from ..figures import _fit
from ..loading import AXES, _dict, _finite, _label, _list, _num
from ..page import _e, _table, fmt_g, fmt_mm

STAT_ROWS = (("nominal_error_mm", "Nominal model"),
             ("ellipsoid_error_mm", "Seed's ellipsoid (eq. 4-5)"),
             ("error_mm", "Current model"),
             ("noise_floor_mm", "Noise floor (repeatability + jig tolerance)"))


def _stat_cells(block: Any) -> Any:
    cells = []
    for a in AXES:
        s = _dict(block, a) or {}
        mean, std = s.get("mean"), s.get("std")
        cells.append(f"{fmt_mm(mean)} ± {fmt_mm(std)}")
        cells.append(fmt_mm(s.get("rms")))
        cells.append(fmt_mm(s.get("max")))
    return cells


def _glitch_words(g: Any) -> str:
    """The samples the dataset's screen set aside, for the Data line ('' when none)."""
    if not isinstance(g, dict) or not _finite(g.get("count")) or g["count"] <= 0:
        return ""
    return (f"; {int(g['count'])} samples at {fmt_g(g.get('positions'))} positions set aside as "
            f"glitches (beyond {fmt_g(g.get('threshold_sd'), 3)} sd of their position's median)")


def _outlier_words(o: Any) -> str:
    """The positions the diagnosis set aside as outliers, for the Data line ('' when none)."""
    if not isinstance(o, dict) or not _finite(o.get("count")) or o["count"] <= 0:
        return ""
    sa = o.get("set_aside")
    pts = [str(x.get("point")) for x in (sa if isinstance(sa, list) else []) if isinstance(x, dict)][:8]
    return (f"; {int(o['count'])} of {fmt_g(o.get('positions_read'))} positions set aside as outliers "
            f"(points {_e(', '.join(pts))}{', ...' if o['count'] > 8 else ''})")


def section_summary(diag: Diag, page: Page) -> None:
    page.add("<h2>1. Summary</h2>")
    _verdict(diag, page)
    _error_table(diag, page)
    facts = _test_facts(diag, page) + _run_facts(diag)
    page.add(_table(["", ""], [[f"<b>{_e(k)}</b>", v] for k, v in facts], "facts"))
    _parameters(diag, page)
    _validation(diag, page)
    _error_figure(diag, page)


def _verdict(diag: Diag, page: Page) -> None:
    verdict = diag.get("verdict")
    explained = diag.get("explained")
    if isinstance(explained, bool):
        badge = ('<span class="ok">explained by the model (consistent with noise)</span>'
                 if explained else
                 '<span class="bad">not explained: structure beyond noise remains</span>')
    else:
        badge = '<span class="na">explained: not given</span>'
        page.note("\"explained\" is not in the diagnosis.")
    page.add(f'<p class="verdict"><b>Model:</b> {_e(_label(diag))} &mdash; {badge}</p>')
    if isinstance(verdict, str) and verdict.strip():
        page.add(f'<p class="verdict">{_e(verdict)}</p>')
    else:
        page.note("No \"verdict\" text in the diagnosis.")


def _error_table(diag: Diag, page: Page) -> None:
    header = ["", "x mean ± std", "x RMS", "x max", "y mean ± std", "y RMS", "y max",
              "z mean ± std", "z RMS", "z max"]
    rows = []
    for key, name in STAT_ROWS:
        block = _dict(diag, key)
        if block is None:
            page.note(f"\"{key}\" is not in the diagnosis; its row shows n/a.")
        rows.append([_e(name)] + _stat_cells(block))
    page.add("<h3>Position error (mm), estimated minus reference, over all samples</h3>")
    page.add(_table(header, rows, "stats"))


def _test_facts(diag: Diag, page: Page) -> Any:
    """(name, HTML) of the statistical tests: chi-square, spatial structure, failing positions."""
    facts = []
    ct = _dict(diag, "chi2_test")
    scale = ct.get("scale") if ct is not None else None
    widened = _finite(scale) and scale > 1.005
    facts.append(("chi²/dof", fmt_g(diag.get("chi2_per_dof"), 4)
                  + (f" (dof {diag['dof']})" if _finite(diag.get("dof")) else "")
                  + (f", p-value {fmt_g(diag['chi2_p_value'], 3)}"
                     if _finite(diag.get("chi2_p_value")) else "")
                  + (f" against chi-square(dof / {fmt_g(scale, 3)}) after dividing by {fmt_g(scale, 3)}: "
                     "widened for the plate's hole errors, which repeat at every height (Satterthwaite)"
                     if widened else "")))
    st = _dict(diag, "structure")
    if st is not None:
        vs = st.get("variance_scale")
        facts.append(("Spatial structure statistic", fmt_g(st.get("statistic"), 4)
                      + (f" (divided by √{fmt_g(vs, 3)} for the plate's holes)" if _finite(vs) and vs > 1.005 else "")
                      + (f" ({_e(st['method'])})" if isinstance(st.get("method"), str) else "")))
        facts.append(("Structure p-value", fmt_g(st.get("p_value"), 3)))
    else:
        page.note("\"structure\" (spatial-structure test) is not in the diagnosis.")
    if _finite(diag.get("failing_positions")):
        facts.append(("Failing positions", str(int(diag["failing_positions"]))))
    return facts


def _run_facts(diag: Diag) -> Any:
    """(name, HTML) of the jig, the fit, the data, the device and the tool."""
    facts = _jig_facts(diag)
    fit = _dict(diag, "fit")
    if fit is not None:
        facts.append(("Fit", _fit_words(fit)))
    jig = _dict(diag, "jig")
    if jig is not None:
        # The jig's own errors (plate holes, fixture heights), named as the
        # jig's by the diagnosis and taken out of its tests.
        texts = [t for t in (jig.get("text") or []) if isinstance(t, str)]
        holes: Any = jig.get("holes") if isinstance(jig.get("holes"), dict) else {}
        hs = holes.get("std_mm") if isinstance(holes.get("std_mm"), dict) else {}
        line = "; ".join(_e(t) for t in texts) if texts else "nothing of the jig's own beyond its tolerance"
        if hs:
            line += (" (hole error std x, y, z: "
                     + ", ".join(fmt_g(hs.get(a), 3) for a in ("x", "y", "z")) + " mm)")
        facts.append(("The jig as it is", line))
    el = _dict(diag, "ellipsoid")
    if el is not None:
        facts.append(("Seed ellipsoid L, M, N (mm)",
                      ", ".join(fmt_g(el.get(k), 6) for k in ("L", "M", "N"))))
    data = _dict(diag, "data")
    if data is not None:
        facts.append(("Data", _data_words(data)))
    dev = _dict(diag, "device")
    if dev is not None:
        facts.append(("Device (mm)", ", ".join(
            f"{k[0]} = {fmt_g(dev.get(k), 6)}" for k in ("a_mm", "b_mm", "m_mm"))))
    if isinstance(diag.get("version"), str):
        facts.append(("Produced by", _e(f"{diag.get('tool', '?')} {diag['version']}")
                      + (f" in {fmt_g(diag['seconds'], 3)} s" if _finite(diag.get("seconds"))
                         else "")))
    return facts


def _jig_facts(diag: Diag) -> Any:
    jt = _dict(diag, "jig_tolerance_mm")
    if jt is None:
        return []
    pa = jt.get("per_axis")
    pa = (" per axis " + ", ".join(f"{a} {fmt_mm(_num(v))}" for a, v in zip(AXES, pa))
          if isinstance(pa, list) and len(pa) == 3 else "")
    ph = jt.get("plate_holes")
    ph = ("; of it shared by a hole at every height (weighed as one block per hole): "
          + ", ".join(f"{a} {fmt_mm(_num(v))}" for a, v in zip(AXES, ph))
          if isinstance(ph, list) and len(ph) == 3 and any(_finite(v) and _num(v) > 0 for v in ph) else "")
    return [("Jig tolerance", f"{fmt_mm(jt.get('value'))} mm "
             f"({_e(jt.get('source', 'source not given'))}){pa}{ph}")]


def _fit_words(fit: Any) -> str:
    conv = fit.get("converged")
    return (f"{_e(fit.get('algorithm', '?'))}, "
            f"{fmt_g(fit.get('evaluations'))} evaluations, "
            f"{fmt_g(fit.get('seconds'), 3)} s, "
            + ("converged" if conv is True else
               "<span class=\"bad\">NOT converged</span>" if conv is False else
               "convergence not given")
            + (f"; {fmt_g(fit['free_parameters'])} free parameters"
               if _finite(fit.get("free_parameters")) else "")
            + (f"; {_e(fit['message'])}" if isinstance(fit.get("message"), str)
               and fit["message"] else ""))


def _data_words(data: Any) -> str:
    hs = data.get("heights")
    hs = ", ".join(fmt_g(_num(h), 6) for h in hs) if isinstance(hs, list) else "n/a"
    ign = data.get("ignored_columns")
    return (f"{_e(data.get('path', '?'))}: {fmt_g(data.get('rows'))} rows, "
            f"{fmt_g(data.get('positions'))} positions, heights {hs} mm"
            + (f"; ignored columns: {_e(', '.join(map(str, ign)))}"
               if isinstance(ign, list) and ign else "")
            + (f"; {int(data['out_of_workspace_samples'])} samples out of the "
               f"workspace" if _finite(data.get("out_of_workspace_samples"))
               and data["out_of_workspace_samples"] > 0 else "")
            + _glitch_words(data.get("glitches"))
            + _outlier_words(data.get("outliers")))


def _parameters(diag: Diag, page: Page) -> None:
    params = _dict(diag, "params")
    page.add("<h3>Fitted parameters</h3>")
    prow = []
    if params:
        for eff, ps in params.items():
            if not isinstance(ps, dict):
                continue
            for pname, p in ps.items():
                p = p if isinstance(p, dict) else {"value": p}
                prow.append([_e(eff), _e(pname), fmt_g(p.get("value"), 6),
                             fmt_g(p.get("std"), 3), _e(p.get("unit", ""))])
    if prow:
        page.add(_table(["effect", "parameter", "value", "std", "unit"], prow, "params"))
    else:
        page.add("<p>No fitted parameters (nominal model or not given).</p>")


def _validation(diag: Diag, page: Page) -> None:
    val = _dict(diag, "validation")
    if val is None:
        page.add("<p>No cross-validation in the diagnosis (it needs fitted parameters and "
                 "more than one height).</p>")
        return
    page.add(f"<h3>Validation ({_e(val.get('method', 'method not given'))})</h3>")
    vrows = []
    for fold in _list(val, "folds") or []:
        if not isinstance(fold, dict):
            continue
        r = _dict(fold, "rms_mm") or {}
        vrows.append([f"held out {fmt_g(fold.get('height'), 6)} mm"]
                     + [fmt_mm(r.get(a)) for a in AXES])
    r = _dict(val, "rms_mm") or {}
    vrows.append(["<b>all held-out positions</b>"] + [fmt_mm(r.get(a)) for a in AXES])
    ins = _dict(val, "in_sample_rms_mm")
    if ins is not None:
        vrows.append(["in sample (fitted on all heights)"] + [fmt_mm(ins.get(a)) for a in AXES])
    page.add(_table(["fold", "x RMS (mm)", "y RMS (mm)", "z RMS (mm)"], vrows, "stats"))
    page.add("<p>Held-out error well above the in-sample error means the added effect "
             "fits noise or one height's peculiarity rather than the device.</p>")


def _error_figure(diag: Diag, page: Page) -> None:
    """A bar chart of the four RMS rows."""
    blocks = [(name, _dict(diag, key)) for key, name in STAT_ROWS]
    blocks = [(n, b) for n, b in blocks if b is not None]
    if not blocks:
        return

    def draw() -> Any:
        fig, ax = plt.subplots(figsize=(7.5, 3.6))
        w = 0.8 / len(blocks)
        for i, (name, b) in enumerate(blocks):
            vals = [_num((_dict(b, a) or {}).get("rms")) for a in AXES]
            ax.bar(np.arange(3) + (i - (len(blocks) - 1) / 2) * w, vals, w, label=name)
        ax.set_xticks(range(3), [f"{a} error" for a in AXES])
        ax.set_ylabel("RMS (mm)")
        ax.set_title("Position error RMS per axis")
        ax.legend(fontsize=8)
        ax.grid(axis="y", alpha=0.3)
        _fit(fig, np.array([[ax]]))
        return fig
    page.figure("error_summary.png", draw, "RMS error per axis",
                "RMS of the position error per axis for "
                "the nominal model, the seed's ellipsoid, the current model and the "
                "noise floor. The current model is done when its bars reach the "
                "noise floor's.")
