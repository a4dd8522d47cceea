"""Section 5: the residual against the physical variables (cable lengths and
angles, height, distance from the centre), with the diagnosis's findings on
the panels they are about."""
from __future__ import annotations

from typing import Any, Dict, List, Optional, TYPE_CHECKING, Tuple

if TYPE_CHECKING:
    from ..page import Page
    from ..loading import Positions

from ..loading import Diag

import math
import re

import numpy as np
import matplotlib.pyplot as plt

from ..figures import _annot, _binned, _dots, _fit
from ..loading import AXES, _dict, _finite, _list, _num
from ..page import _e, _table, fmt_g


_VARIABLE_KINDS = ("height", "radius", "length", "angle")


def _finding_target(f: Any) -> Any:
    """Map a finding to (panel kind, cable number or None).

    A diagnosis carries the structured fields "variable_kind" and "cable"
    (docs/calibration.md); files written before they existed only name the
    variable in English, which is read as a fallback.
    """
    if not isinstance(f, dict):  # a bare variable name
        return _finding_target_from_name(f)
    vk = f.get("variable_kind")
    if vk in _VARIABLE_KINDS:
        c = f.get("cable")
        cable = int(c) if isinstance(c, (int, float)) and not isinstance(c, bool) and 1 <= c <= 4 else None
        return vk, cable if vk in ("length", "angle") else None
    return _finding_target_from_name(f.get("variable"))


def _finding_target_from_name(var: Any) -> Any:
    v = str(var).lower()
    m = re.search(r"([1-4])", v)
    cable = int(m.group(1)) if m else None
    if "angle" in v:
        return "angle", cable
    if "height" in v or v in ("x_ref", "h"):
        return "height", None
    if "dist" in v or "radi" in v or v in ("r", "rho"):
        return "radius", None
    if "len" in v or re.fullmatch(r"l[1-4]", v) or "cable" in v:
        return "length", cable
    return None, None


def _finding_text(f: Any) -> str:
    t = f.get("text")
    if isinstance(t, str) and t:
        return t if len(t) <= 70 else t[:67] + "..."
    s = f"{f.get('kind', '?')} in {f.get('axis', '?')}"
    if _finite(f.get("period_mm")):
        s += f", period {fmt_g(f['period_mm'], 4)} mm"
    if _finite(f.get("amplitude_mm")):
        s += f", amplitude {fmt_g(f['amplitude_mm'], 3)} mm"
    return s


def _route_findings(findings: List[Any]) -> Any:
    """Route each finding to the panel it is about.

    Returns (pos_notes, len_notes, periods): position-residual findings (axis x, y
    or z) keyed by (variable kind, axis index) for vs_variables.png; cable-reading
    findings keyed by cable (1..4, None = all cables) for vs_cable_length.png; and
    (cable, period_mm) of periodic cable-length findings.
    """
    pos_notes: Dict[Tuple[str, int], List[str]] = {}
    len_notes: Dict[Optional[int], List[str]] = {}
    periods: List[Tuple[Optional[int], float]] = []
    for f in findings:
        kind, cable = _finding_target(f)
        axis = str(f.get("axis", "")).strip().lower()
        text = _finding_text(f)
        if axis in AXES and kind is not None:
            pos_notes.setdefault((kind, AXES.index(axis)), []).append(text)
        elif kind == "length" or axis.startswith("l"):
            m = re.fullmatch(r"l([1-4])", axis)
            c = cable if cable is not None else (int(m.group(1)) if m else None)
            len_notes.setdefault(c, []).append(text)
            per = _num(f.get("period_mm"))
            if math.isfinite(per) and per > 0:
                periods.append((c, per))
    return pos_notes, len_notes, periods


def _route_trends(diag: Diag, page: Page, pos_notes: Dict[Any, List[str]], len_notes: Dict[Any, List[str]]) -> None:
    """The library's test of each plotted series (positions.trends: a one-way
    analysis of variance over bins of the variable, Bonferroni over the
    series): each significant one annotates its panel, and the text lists
    them, so the page never shows a trend the words deny."""
    trends = [t for t in (_list(_dict(diag, "positions") or {}, "trends") or [])
              if isinstance(t, dict) and t.get("significant") is True]
    if not trends:
        return
    items = []
    for t in trends:
        var, axis, cable = str(t.get("variable", "?")), str(t.get("axis", "?")), t.get("cable")
        who = f"cable {cable} " if isinstance(cable, int) and not isinstance(cable, bool) else ""
        note = (f"{who}{var}: trend, range {fmt_g(t.get('range_mm'), 2)} mm "
                f"(F-test p = {fmt_g(t.get('p_value'), 2)})")
        if t.get("panel") == "vs_cable_length":
            len_notes.setdefault(cable, []).append(note)
            items.append(f"cable {cable}'s reading against its length")
        elif axis in AXES:
            pos_notes.setdefault((var, AXES.index(axis)), []).append(note)
            items.append(f"{axis} against {who}{var}")
    page.add("<p>The residuals plotted below vary with the variable in " + str(len(items)) + " of their series "
             "(a one-way analysis of variance of the residual over ten bins of equal count of the variable, "
             "Bonferroni over every series plotted, level 1e-3): " + _e("; ".join(items[:12]))
             + ("; ..." if len(items) > 12 else "") + ". The position residual is the current model's; the "
             "findings above are about the residual they name.</p>")


def section_variables(diag: Diag, page: Page, P: Positions) -> None:
    page.add("<h2>5. Residual versus physical variables</h2>")
    pos_notes, len_notes, periods = _route_findings(_findings(diag, page))
    _route_trends(diag, page, pos_notes, len_notes)
    if not P.ok:
        page.add("<p>Plots not available: no per-position data.</p>")
        return
    pal = plt.get_cmap("tab10")
    if P.lengths is not None and P.length_residual is not None:
        _length_figure(page, P, pal, len_notes, periods)
    else:
        page.note("\"positions.lengths_mm\" or \"positions.length_residual_mm\" is missing: "
                  "no length-residual plot.")
    _variables_figure(page, P, pal, pos_notes)


def _findings(diag: Diag, page: Page) -> Any:
    """The diagnosis's findings (dicts), after adding their summary and table to the page."""
    us = _dict(diag, "unexplained_structure")
    findings: List[Any] = []
    if us is None:
        page.note("\"unexplained_structure\" is not in the diagnosis.")
        return findings
    if isinstance(us.get("summary"), str):
        page.add(f"<p>{_e(us['summary'])}</p>")
    findings = [f for f in (_list(us, "findings") or []) if isinstance(f, dict)]
    if findings:
        rows = [[_e(f.get("variable", "?")), _e(f.get("kind", "?")), _e(f.get("axis", "?")),
                 fmt_g(f.get("period_mm"), 4), fmt_g(f.get("amplitude_mm"), 4),
                 fmt_g(f.get("p_value"), 3), _e(f.get("text", ""))] for f in findings]
        page.add(_table(["variable", "kind", "axis", "period (mm)", "amplitude (mm)",
                         "p-value", "finding"], rows, "cands"))
    else:
        of = us.get("residual_of")
        page.add("<p>No finding in the residual"
                 + (f" of {_e(of)}" if isinstance(of, str) and of else "") + ".</p>")
    return findings


def _length_figure(page: Page, P: Positions, pal: Any, len_notes: Dict[Optional[int], List[str]], periods: Any) -> None:
    """Length residual per cable vs that cable's length."""
    def draw() -> Any:
        fig, axs = plt.subplots(2, 2, figsize=(10, 7.5))
        for i, ax in enumerate(axs.ravel()):
            x, y = P.lengths[:, i], P.length_residual[:, i]
            _dots(ax, x, y, 6, pal(i), 0.35, label="positions")
            # bins narrow enough to show a periodicity the diagnosis found here
            per = [p for c, p in periods if c in (i + 1, None)]
            _binned(ax, x, y, width=min(per) / 5 if per else None)
            ax.axhline(0, color="0.6", lw=0.8)
            ax.set_xlabel(f"cable {i + 1} mean measured length (mm)")
            ax.set_ylabel(f"cable {i + 1} length residual (mm)")
            ax.set_title(f"Cable {i + 1}: measured - predicted reading")
            ax.grid(alpha=0.3)
            _annot(ax, len_notes.get(i + 1, []) + (len_notes.get(None, []) if i == 0 else []))
        axs[0, 0].legend(fontsize=8, loc="lower right")
        _fit(fig, axs)
        return fig
    page.figure("vs_cable_length.png", draw, "length residual versus cable length",
                "Each cable's reading residual (mean measured minus what the model "
                "predicts at the reference position) against that cable's length, "
                "with the binned mean. A slope is a gain error, a curve a "
                "non-linearity, a ripple a periodic effect of the drum or pulley; "
                "red boxes are the diagnosis's own findings.", weight=3)


def _variables_figure(page: Page, P: Positions, pal: Any, pos_notes: Dict[Tuple[str, int], List[str]]) -> None:
    """The position residual against every variable, one column each."""
    res = P.residual if P.residual is not None else P.nominal
    if res is None:
        return
    which = "current model" if P.residual is not None else "nominal model"
    radius = np.hypot(P.ref[:, 1], P.ref[:, 2])
    cols = [("height", P.height, "height x (mm)"),
            ("radius", radius, "distance from the centre √(y²+z²) (mm)")]
    if P.lengths is not None:
        cols.append(("length", P.lengths, "cable length (mm)"))
    if P.angle is not None:
        cols.append(("angle", P.angle, "cable angle out of the cable plane (deg)"))
    else:
        page.note("\"positions.cable_angle_deg\" is missing: no residual-versus-angle plot.")

    def draw() -> Any:
        W, H = 4.2 * len(cols), 9.5
        fig, axs = plt.subplots(3, len(cols), figsize=(W, H), squeeze=False, sharey="row")
        # Margins in inches (tick labels, axis labels, titles), not constrained
        # layout: it measured the tick labels of these twelve panels twice.
        fig.subplots_adjust(left=0.75 / W, right=1 - 0.15 / W, bottom=0.6 / H,
                            top=1 - 0.75 / H, wspace=0.12, hspace=0.32)
        for k in range(3):
            for j, (kind, xv, xl) in enumerate(cols):
                ax = axs[k, j]
                r = res[:, k]
                if xv.ndim == 2:  # one series per cable
                    for i in range(4):
                        _dots(ax, xv[:, i], r, 4, pal(i), 0.25)
                        _binned(ax, xv[:, i], r, color=pal(i), label=f"cable {i + 1}")
                    if k == 0:
                        ax.legend(fontsize=7, loc="lower right")
                else:
                    _dots(ax, xv, r, 5, "C0", 0.35)
                    _binned(ax, xv, r)
                ax.axhline(0, color="0.6", lw=0.8)
                ax.set_xlabel(xl, fontsize=8.5)
                if j == 0:
                    ax.set_ylabel(f"{AXES[k]} residual (mm)")
                ax.grid(alpha=0.3)
                if k == 0:
                    ax.set_title(f"vs {xl.split(' (')[0]}", fontsize=10)
                _annot(ax, pos_notes.get((kind, k), []))
        fig.suptitle(f"Position residual ({which}) versus physical variables")
        return fig
    page.figure("vs_variables.png", draw, "residual versus variables",
                f"Per-position residual of the {which} (rows x, y, z) against the height, "
                f"the distance from the centre, each cable's length and each cable's angle "
                f"out of the cable plane (one colour per cable), with binned means; red "
                f"boxes are the diagnosis's trend findings. Flat lines at zero mean "
                f"nothing is left; a trend or bump says which variable the missing effect "
                f"depends on.", weight=len(cols) + 1)
