"""Section 2b: the accuracy map. The fitted model's predicted position error
(its parameters' covariance propagated to the position: the library's
accuracy_map, none of it recomputed here: the figures read its arrays) on each x level of the grid, the
jig's volume outlined and the levels past it marked as extrapolated, and a
section through the workspace at the plate's centre."""
from __future__ import annotations

from typing import Any, Dict, TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from ..page import Page

import numpy as np
import matplotlib.pyplot as plt

from ..loading import Diag, _dict, _num
from ..page import _e, fmt_g


def _grid(a: Any) -> Any:
    """What the figures need of the map, as arrays (None: NaN); ValueError
    when the JSON is not a map."""
    g = a.get("grid")
    if not isinstance(g, dict):
        raise ValueError(str(a.get("error", "no grid")))
    m: Dict[str, Any] = {k: np.asarray(g[k + "_mm"], dtype=float) for k in "xyz"}
    m["radius95"] = np.asarray([np.nan if v is None else v for v in a["radius95_mm"]], dtype=float)
    m["inside"] = np.asarray(a["inside"], dtype=bool)
    m["levels"] = np.asarray(g["levels_mm"], dtype=float)
    m["ny"], m["nz"] = int(g["ny"]), int(g["nz"])
    if not all(len(m[k]) == len(m["levels"]) * m["ny"] * m["nz"] for k in ("x", "y", "z", "radius95", "inside")):
        raise ValueError("the map's arrays do not match its grid")
    return m


def section_accuracy(diag: Diag, page: Page) -> None:
    a = _dict(diag, "accuracy_map")
    if a is None:
        return
    page.add("<h2>2b. How accurate the calibration is where you work</h2>")
    try:
        m = _grid(a)
    except (ValueError, KeyError, TypeError) as e:
        page.add(f"<p>Not available: {_e(str(e))}.</p>")
        return
    inside = _dict(_dict(a, "summary") or {}, "inside") or {}
    outside = _dict(_dict(a, "summary") or {}, "outside") or {}
    sig = _dict(inside, "sigma_mm") or {}
    r_in, r_out = _dict(inside, "radius95_mm") or {}, _dict(outside, "radius95_mm") or {}
    page.add("<p>The position error the fitted model's own uncertainty leaves (its parameters' covariance, "
             "robust to errors a plate hole's positions share, propagated to the position). Over the jig's volume: "
             "1-sigma mean x " + " y ".join(fmt_g(_num((_dict(sig, k) or {}).get("mean")), 3) for k in "xyz")
             + " mm (z last); the 95 % ellipsoid's longest semi-axis "
             f"{fmt_g(_num(r_in.get('mean')), 3)} mm on average, {fmt_g(_num(r_in.get('max')), 3)} mm at worst; "
             f"past the jig (extrapolated) up to {fmt_g(_num(r_out.get('max')), 3)} mm. It is the calibration's "
             "error from the fit alone: a missing effect adds to it (section 3), and <code>cdm calib check</code> "
             "measures it on another session.</p>")
    page.figure("accuracy_map.png", lambda: _draw_levels(m), "accuracy map per level",
                "The 95 % ellipsoid's longest semi-axis (mm) on each x level of the grid (y right, z up); the "
                "dashed box is the jig's plate, levels marked \u201cpast the jig\u201d are extrapolated. One "
                "colour scale for all.", weight=2)
    page.figure("accuracy_section.png", lambda: _draw_section(m), "accuracy section",
                "A section through the workspace at the plate's centre in z: the 95 % ellipsoid's longest "
                "semi-axis (mm) over x and y; the dashed box is the jig's volume.", weight=1)


def _box(ax: Any, m: Any, u: str, v: str) -> None:
    ins = m["inside"]
    if ins.any():
        lo_u, hi_u, lo_v, hi_v = m[u][ins].min(), m[u][ins].max(), m[v][ins].min(), m[v][ins].max()
        ax.plot([lo_u, hi_u, hi_u, lo_u, lo_u], [lo_v, lo_v, hi_v, hi_v, lo_v], "k--", lw=0.8)


def _draw_levels(m: Any) -> Figure:
    levels, ny, nz = m["levels"], m["ny"], m["nz"]
    n = len(levels)
    cols = min(4, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 3.0 * rows), squeeze=False, layout="constrained")
    r95 = m["radius95"]
    vmax = float(np.nanmax(r95)) if np.isfinite(r95).any() else 1.0
    im = None
    for k, x in enumerate(levels):
        ax = axes[k // cols][k % cols]
        sl = slice(k * ny * nz, (k + 1) * ny * nz)
        v = r95[sl].reshape(nz, ny)
        y, z = m["y"][sl].reshape(nz, ny), m["z"][sl].reshape(nz, ny)
        im = ax.imshow(v, origin="lower", vmin=0, vmax=vmax, cmap="viridis", interpolation="nearest",
                       extent=(y.min(), y.max(), z.min(), z.max()))
        past = not m["inside"][sl].any()
        ax.set_title(f"x = {x:.1f} mm" + (" (past the jig)" if past else ""), fontsize=9)
        if not past:
            sub = {key: m[key][sl] for key in ("y", "z", "inside")}
            _box(ax, sub, "y", "z")
        ax.set_xlabel("y (mm)")
        ax.set_ylabel("z (mm)")
    for k in range(n, rows * cols):
        axes[k // cols][k % cols].axis("off")
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.8, label="95 % radius (mm)")
    return fig


def _draw_section(m: Any) -> Figure:
    levels, ny, nz = m["levels"], m["ny"], m["nz"]
    n = len(levels)
    iz = nz // 2
    idx = np.array([k * ny * nz + iz * ny + iy for k in range(n) for iy in range(ny)])
    v = m["radius95"][idx].reshape(n, ny)
    y = m["y"][idx].reshape(n, ny)
    fig, ax = plt.subplots(figsize=(6, 3.5), layout="constrained")
    ext = (y.min(), y.max(), levels[0], levels[-1])
    im = ax.imshow(v, origin="lower", aspect="auto", cmap="viridis", extent=ext, interpolation="nearest")
    sub = {"y": m["y"][idx], "x": m["x"][idx], "inside": m["inside"][idx]}
    _box(ax, sub, "y", "x")
    ax.set_xlabel("y (mm)")
    ax.set_ylabel("x (mm)")
    ax.set_title(f"z = {m['z'][idx][0]:.1f} mm", fontsize=9)
    fig.colorbar(im, ax=ax, label="95 % radius (mm)")
    return fig
