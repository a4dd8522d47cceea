"""Section 2: the residual maps per height, and the seed's cut view through the centre."""
from __future__ import annotations

from typing import Any, List, TYPE_CHECKING, Tuple

if TYPE_CHECKING:
    from ..page import Page
    from ..loading import Positions

from ..loading import Diag

import functools

import numpy as np
import matplotlib.pyplot as plt

from ..figures import (_colorbar, _crosses, _drop_frames, _fit, _keep, _kept, _map, _map_grid,
                       _outer_labels, _raster, _regular_grid, _symnorm)
from ..loading import AXES, _label
from ..page import _e


def section_maps(diag: Diag, page: Page, P: Positions) -> None:
    page.add("<h2>2. Residual maps per height</h2>")
    if not P.ok or (P.residual is None and P.nominal is None):
        page.add("<p>Not available (see the notes).</p>")
        return
    cols, how, cut = _columns(diag, P)
    maps = _Maps(P, cols)
    for h, idx in zip(P.heights, P.height_index):
        page.figure(f"residual_map_h{h:g}.png".replace("-", "m"),
                    functools.partial(maps.draw, h, idx), f"residual maps at {h:g} mm",
                    f"Height {h:g} mm: residual per jig position in the cable plane "
                    f"(y right, z up), rows x, y, z; {_e(how)}"
                    + (", and the current residual again on its own colour scale"
                       if maps.ncol > len(cols) else "")
                    + ". One symmetric colour scale per axis for all "
                    f"heights (arrows on a colour bar: a few outliers beyond it are "
                    f"drawn at its ends); black crosses mark positions whose mean residual "
                    f"is beyond what noise and jig tolerance explain.", weight=maps.ncol,
                    group="residual_map", build=2)
    if len(P.heights) == 1:
        page.note("Only one height in the data: the x error cannot be separated from a "
                  "height-dependent effect.")
    section_cut(page, P, *cut)


def _columns(diag: Diag, P: Positions) -> Any:
    """The maps' columns [(values, title, current)], the caption's words for them,
    and the cut view's (solid, solid name, dashed, dashed name)."""
    model = diag.get("model")
    if isinstance(model, list) and not model:
        # The nominal model is the current one: compare it with the seed's baseline.
        cur = P.residual if P.residual is not None else P.nominal
        cols = [(cur, "current: nominal model", True),
                (P.ellipsoid, "seed's ellipsoid", False)]
        how = ("left the nominal model (the current one), right the seed's ellipsoid "
               "(the baseline to beat)")
        cut = (cur, "nominal (current)", P.ellipsoid, "seed's ellipsoid")
    else:
        cols = [(P.nominal, "before: nominal model", False),
                (P.residual, f"after: {_label(diag)}", True)]
        how = "left before (nominal model), right after (current model)"
        cut = (P.residual, "current model", P.nominal, "nominal")
    return [c for c in cols if c[0] is not None], how, cut


class _Maps:
    """The residual maps of every height: one layout and colour scale for all."""

    def __init__(self, P: Positions, cols: Any) -> None:
        self.P, self.cols = P, cols
        self.norms = norms = [_symnorm(*[c[0][:, k] for c in cols]) for k in range(3)]
        # The current residual again on its own scale when the shared one washes it out,
        # so that what is left (the next missing effect) is visible.
        cur: Any = next((c[0] for c in cols if c[2]), None)
        self.zoom = zoom = [None] * 3
        if cur is not None and len(cols) > 1:
            for k in range(3):
                nk = _symnorm(cur[:, k])
                if nk.vmax < norms[k].vmax / 3:
                    zoom[k] = nk
        self.ncol = ncol = len(cols) + (1 if any(zoom) else 0)
        self.groups = [len(cols)] + ([1] if ncol > len(cols) else [])
        # The panels: (row, column, values over all positions, norm, crosses marked).
        self.panels: List[Tuple[int, int, Any, Any, bool]] = []
        panels = self.panels
        for k in range(3):
            for j, (arr, title, current) in enumerate(cols):
                panels.append((k, j, arr[:, k], norms[k], current))
            if ncol > len(cols) and zoom[k] is not None:
                panels.append((k, ncol - 1, cur[:, k], zoom[k], True))
        # Same layout at every height on the same grid: a process redraws its last figure.
        self.signature = (ncol, tuple(cols[j][1] for j in range(len(cols))))

    def suptitle(self, h: Any, idx: Any) -> Any:
        nf = int(self.P.failing[idx].sum())
        return (f"Residual (estimate - reference) at height x = {h:g} mm"
                + (f"; {nf} failing positions marked ×" if nf else ""))

    def redraw(self, h: Any, idx: Any, g: Any) -> Any:
        """The last figure drawn, with this height's data, or None if it cannot be."""
        P = self.P
        last = _kept("residual_map")
        if g is None or last is None or last[0] != (self.signature, g[0].tobytes(), g[1].tobytes()):
            return None
        _, fig, handles = last
        y, z = P.ref[idx, 1], P.ref[idx, 2]
        fail = P.failing[idx]
        for i, ((k, j, vals, norm, marked), (im, cross)) in enumerate(zip(self.panels, handles)):
            im.set_data(_raster(g, vals[idx]))
            if marked:
                if cross is None and fail.any():
                    handles[i] = (im, _crosses(im.axes, y[fail], z[fail]))
                elif cross is not None:
                    cross.set_data(y[fail], z[fail])
        fig.suptitle(self.suptitle(h, idx))
        return fig

    def draw(self, h: Any, idx: Any) -> Any:
        P, cols, ncol = self.P, self.cols, self.ncol
        y, z = P.ref[idx, 1], P.ref[idx, 2]
        g = _regular_grid(y, z)
        fig = self.redraw(h, idx, g)
        if fig is not None:
            return fig
        _drop_frames("residual_map")
        fig, axs, cbs = _map_grid((4.0 * ncol + 1.6 * (ncol - len(cols) + 1), 11), 3, self.groups)
        handles = []
        for k, j, vals, norm, marked in self.panels:
            ax = axs[k, j]
            handles.append(_map(ax, y, z, vals[idx], norm, P.failing[idx] if marked else None, g))
            if j < len(cols):
                ax.set_title(f"{AXES[k]} residual, {cols[j][1]}", fontsize=9)
                if j == len(cols) - 1:
                    _colorbar(fig, handles[-1][0], cbs[k, 0], norm, f"{AXES[k]} residual (mm)")
            else:
                ax.set_title(f"{AXES[k]} residual, current, own scale", fontsize=9)
                _colorbar(fig, handles[-1][0], cbs[k, 1], norm, f"{AXES[k]} residual (mm)")
        for k in range(3):
            if ncol > len(cols) and self.zoom[k] is None:
                ax = axs[k, -1]
                ax.set_axis_off()
                cbs[k, 1].remove()
                ax.text(0.5, 0.5, "current residual:\nsee the shared scale", ha="center",
                        va="center", transform=ax.transAxes, fontsize=9, color="0.4")
        _outer_labels(axs)
        fig.suptitle(self.suptitle(h, idx))
        if g is not None:
            _keep("residual_map", (self.signature, g[0].tobytes(), g[1].tobytes()), fig, handles)
        return fig


def _cut(P: Positions, idx: Any, along: int) -> Any:
    """Indices (into idx) on the grid line nearest the centre, sorted along `along`."""
    other = 2 if along == 1 else 1
    v = P.ref[idx, other]
    ok = np.isfinite(v)
    if not ok.any():
        return None
    u = np.unique(np.round(v[ok], 3))
    c = u[np.argmin(np.abs(u))]
    sel = idx[np.isfinite(v) & (np.abs(np.round(v, 3) - c) < 1e-6)]
    sel = sel[np.argsort(P.ref[sel, along])]
    return sel, c


def section_cut(page: Page, P: Positions, solid: Any, solid_name: str, dashed: Any, dashed_name: str) -> None:
    # The grid lines first: whether there is a cut decides between figure and note.
    cuts = {(along, i): _cut(P, idx, along)
            for along in (1, 2) for i, idx in enumerate(P.height_index)}
    if all(r is None for r in cuts.values()):
        page.note("No grid line through the centre: cut view skipped.")
        return

    def draw() -> Any:
        fig, axs = plt.subplots(1, 2, figsize=(11, 4.2))
        cmap = plt.get_cmap("viridis")
        for a, (along, ax) in enumerate(zip((1, 2), axs)):
            for i, h in enumerate(P.heights):
                r = cuts[(along, i)]
                if r is None:
                    continue
                sel, c = r
                col = cmap(i / max(1, len(P.heights) - 1))
                s = P.ref[sel, along]
                if dashed is not None:
                    ax.plot(s, dashed[sel, 0], "--", color=col, marker=".", ms=3, lw=1)
                if solid is not None:
                    ax.plot(s, solid[sel, 0], "-", color=col, marker="o", ms=3, lw=1.5,
                            label=f"x = {h:g} mm")
            other = "z" if along == 1 else "y"
            ax.axhline(0, color="0.6", lw=0.8)
            ax.set_xlabel(f"{'y' if along == 1 else 'z'} (mm), at {other} nearest 0")
            ax.set_ylabel("x residual (mm)")
            ax.set_title(f"x residual along {'y' if along == 1 else 'z'}")
            ax.grid(alpha=0.3)
        if solid is not None:
            axs[0].legend(fontsize=8, title=f"solid: {solid_name}"
                          + (f"\ndashed: {dashed_name}" if dashed is not None else ""),
                          title_fontsize=8)
        _fit(fig, axs.reshape(1, -1))
        return fig
    also = f", dashed {_e(dashed_name)}" if dashed is not None else ""
    page.figure("residual_cut.png", draw, "x residual cut",
                f"The seed's cut view: x residual along the grid line through the centre, "
                f"one colour per height; solid {_e(solid_name)}{also}. A barrel "
                f"distortion is an arch (x falls short toward the edges) with the same "
                f"curvature at every height.", weight=2)
