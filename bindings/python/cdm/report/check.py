"""The report of a calibration checked on another session (``cdm calib check
--json``, whose "tool" is "cdm calib check"): the error measured at each
position against the error the calibration's accuracy map predicted there.
Nothing is recomputed: the figures read the check's per-position arrays
(predicted.per_position) and its statistics."""
from __future__ import annotations

from typing import Any, Dict, List, Tuple, TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

import math
import os

import numpy as np
import matplotlib.pyplot as plt

from .drawing import _draw_all
from .page import Page, _e, _table, document, fmt_mm, place_figures

TOOL = "cdm calib check"
# The 95 % quantile of chi-square with 3 degrees of freedom.
CHI2_3_95 = 7.814727903251178


def is_check(d: Any) -> bool:
    return isinstance(d, dict) and d.get("tool") == TOOL


def _obj(d: Any, key: str) -> Dict[str, Any]:
    """d[key] when both are objects, else {} (a part missing or malformed)."""
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, dict) else {}


def _per_position(check: Dict[str, Any]) -> Dict[str, Any]:
    """The per-position arrays; ValueError naming what is missing."""
    pp = _obj(check, "predicted").get("per_position")
    if not isinstance(pp, dict):
        raise ValueError(str(_obj(check, "predicted").get("text", "no per-position prediction")))
    m = {k: np.asarray(pp[k], dtype=float) for k in ("ref_mm", "error_mm", "calibration_sigma_mm",
                                                     "expected_sigma_mm", "chi2")}
    n = len(m["chi2"])
    if n == 0 or any(len(v) != n for v in m.values()) or any(m[k].shape != (n, 3) for k in m if k != "chi2"):
        raise ValueError("the per-position arrays do not match")
    return m


def _summary(check: Dict[str, Any], page: Page) -> None:
    page.add("<h2>1. Does the calibration hold here?</h2>")
    mc, pr = _obj(check, "model_check"), _obj(check, "predicted")
    page.add(f"<p><b>{_e(mc.get('text', 'no verdict'))}</b></p>")
    page.add(f"<p>Against its accuracy map: {_e(pr.get('text', 'not available'))}. Test: {_e(pr.get('test', ''))}."
             "</p>")
    pe, nom, err = _obj(check, "position_error_mm"), _obj(check, "nominal_error_mm"), _obj(check, "error_mm")
    cal_rms, noise_rms = _obj(pr, "calibration_rms_mm"), _obj(pr, "noise_and_jig_rms_mm")
    rows = []
    for a in "xyz":
        rows.append([a, fmt_mm(_obj(nom, a).get("rms")), fmt_mm(_obj(err, a).get("rms")),
                     fmt_mm(_obj(pe, a).get("rms")), fmt_mm(cal_rms.get(a)), fmt_mm(noise_rms.get(a))])
    page.add(_table(["axis", "nominal RMS (per sample)", "calibration RMS (per sample)",
                     "per position RMS (measured)", "calibration's predicted RMS", "noise and jig RMS"], rows))
    page.add(f"<p>{_e(check.get('positions', 0))} positions; failing: "
             f"{_e(_obj(check, 'failing').get('count', 'n/a'))}. {_e(_obj(check, 'jig').get('text', ''))}</p>")


def _draw_predicted(m: Dict[str, Any]) -> Figure:
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    err = np.linalg.norm(m["error_mm"], axis=1)
    exp = np.linalg.norm(m["expected_sigma_mm"], axis=1)
    a1.scatter(exp, err, s=6, alpha=0.5, color="C0", label="positions")
    top = float(max(exp.max(), 1e-9))
    xs = np.linspace(0, top * 1.05, 2)
    # |e| for a Gaussian error of equal variance per axis at its 95 % quantile.
    a1.plot(xs, xs * math.sqrt(CHI2_3_95 / 3), "k--", lw=0.8, label="95 % (chi-square, 3 dof)")
    a1.set_xlabel("expected error (mm): noise, jig and calibration, 1-sigma length")
    a1.set_ylabel("measured error (mm): position's mean error length")
    a1.legend(fontsize=8)
    c2 = m["chi2"]
    hi = float(max(np.quantile(c2, 0.99), CHI2_3_95 * 1.5))
    bins = np.linspace(0, hi, 40)
    a2.hist(np.clip(c2, 0, hi), bins=bins, density=True, color="C0", alpha=0.6, label="positions")
    x = np.linspace(1e-3, hi, 200)
    a2.plot(x, np.sqrt(x) * np.exp(-x / 2) / math.sqrt(2 * math.pi), "k-", lw=1,
            label="chi-square, 3 dof (as predicted)")
    a2.axvline(CHI2_3_95, color="k", ls="--", lw=0.8)
    a2.set_xlabel("each position's chi-square against its expected error")
    a2.set_ylabel("density")
    a2.legend(fontsize=8)
    return fig


# More distinct heights than this (positions placed freely, not on a
# plate's fixtures): one y-z panel for them all.
MAX_PANELS = 8


def _draw_maps(m: Dict[str, Any]) -> Figure:
    ref = m["ref_mm"].copy()
    ref[:, 0] = np.round(ref[:, 0], 2)  # a fixture height, to 0.01 mm
    heights = np.unique(ref[:, 0])
    if len(heights) > MAX_PANELS:
        heights = np.array([np.nan])
        ref[:, 0] = np.nan
    n = len(heights)
    fig, axes = plt.subplots(2, n, figsize=(3.0 * n + 1, 5.6), squeeze=False, layout="constrained")
    err = np.linalg.norm(m["error_mm"], axis=1)
    cal = np.linalg.norm(m["calibration_sigma_mm"], axis=1)
    for row, (v, label) in enumerate(((err, "measured error (mm)"), (cal, "calibration's predicted 1-sigma (mm)"))):
        vmax = float(np.nanmax(v)) if np.isfinite(v).any() else 1.0
        sc = None
        for k, h in enumerate(heights):
            ax = axes[row][k]
            sel = (ref[:, 0] == h) | np.isnan(h)
            sc = ax.scatter(ref[sel, 1], ref[sel, 2], c=v[sel], s=14, vmin=0, vmax=vmax, cmap="viridis")
            ax.set_title("every height" if np.isnan(h) else f"height {h:g} mm", fontsize=9)
            ax.set_xlabel("y (mm)")
            ax.set_ylabel("z (mm)")
            ax.set_aspect("equal")
        if sc is not None:
            fig.colorbar(sc, ax=list(axes[row]), shrink=0.8, label=label)
    return fig


def render_check(path: str, check: Dict[str, Any], tmp: str) -> Tuple[str, List[str]]:
    """The page and figures for a check, drawn into tmp: (html, figure names)."""
    page = Page()
    _summary(check, page)
    page.add("<h2>2. Measured against predicted, position by position</h2>")
    try:
        m = _per_position(check)
    except (ValueError, KeyError, TypeError) as e:
        page.add(f"<p>Not available: {_e(str(e))}.</p>")
        page.note(f"no per-position prediction: {e}")
    else:
        page.figure("check_predicted.png", lambda: _draw_predicted(m), "measured against predicted error",
                    "Left: each position's measured mean error against the error expected there (its noise, the "
                    "jig's tolerance and the calibration's propagated covariance, as 1-sigma lengths); the dashed "
                    "line is where 95 % of the positions should fall below. Right: each position's chi-square "
                    "against its expected error, beside the chi-square of 3 degrees of freedom (the jig's "
                    "placement and the fixture heights' offsets, fitted on this session, take a little of it: "
                    "the terms run slightly below that curve when the calibration is as predicted; the test "
                    "counts them out).", weight=1)
        page.figure("check_maps.png", lambda: _draw_maps(m), "measured and predicted error per height",
                    "Per fixture height (y right, z up): top, the measured error's length at each position; "
                    "bottom, the calibration's own predicted 1-sigma there (the accuracy map at the positions).",
                    weight=2)
    _draw_all(page.figures, tmp)
    figs = place_figures(page, path)
    effects = ", ".join(str(e) for e in check.get("effects") or [])
    title = "cdm calibration check" + (": " + effects if effects else "")
    doc = document(title, _e(os.path.basename(path)), page.notes, page.toc,
                   [p for p in page.parts if isinstance(p, str)])
    return doc, figs


__all__ = ["is_check", "render_check"]
