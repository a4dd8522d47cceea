"""Drawing helpers shared by the sections: residual maps on the jig's grid, the
symmetric colour scale, fixed layouts in inches, the figure kept for redrawing,
and the PNG writer."""
from __future__ import annotations

from typing import Any, Dict, Optional, TYPE_CHECKING, Tuple

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

import math

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import PIL.Image  # noqa: E402  (matplotlib's own dependency)
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402

CMAP = "RdBu_r"
DPI = 100


def _regular_grid(y: Any, z: Any) -> Any:
    """(ycentres, zcentres, iy, iz) when (y, z) lie on a regular grid, else None."""
    ok = np.isfinite(y) & np.isfinite(z)
    if ok.sum() < 4 or not ok.all():
        return None
    out = []
    for v in (y, z):
        u = np.unique(np.round(v, 3))
        if len(u) < 2:
            return None
        d = np.diff(u)
        pitch = d.min()
        steps = d / pitch
        if pitch <= 0 or not np.allclose(steps, np.round(steps), atol=0.02):
            return None
        n = int(round((u[-1] - u[0]) / pitch)) + 1
        if n > 400:
            return None
        idx = np.round((v - u[0]) / pitch).astype(int)
        out.append((u[0] + pitch * np.arange(n), idx))
    (yc, iy), (zc, iz) = out
    if len(yc) * len(zc) > 4 * len(y):  # too sparse to draw as a raster
        return None
    return yc, zc, iy, iz


def _edges(c: Any) -> Any:
    if len(c) == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    p = c[1] - c[0]
    return np.concatenate([c - p / 2, [c[-1] + p / 2]])


def _raster(g: Any, v: Any) -> Any:
    """Values v on the regular grid g (from _regular_grid), nan where no position."""
    yc, zc, iy, iz = g
    G = np.full((len(zc), len(yc)), np.nan)
    G[iz, iy] = v
    return np.ma.masked_invalid(G)


def _map(ax: Axes, y: Any, z: Any, v: Any, norm: Any, failing: Any = None, g: Any = None) -> Any:
    """Draw values v at (y, z): raster on a regular grid (g, from _regular_grid(y, z)),
    scatter otherwise. Returns (mappable, the line of failing crosses or None)."""
    if g is not None:
        ey, ez = _edges(g[0]), _edges(g[1])
        m: Any = ax.imshow(_raster(g, v), cmap=CMAP, norm=norm, origin="lower",
                      extent=(ey[0], ey[-1], ez[0], ez[-1]), interpolation="nearest")
    else:
        s = max(8.0, min(200.0, 4000.0 / max(1, len(y))))
        m = ax.scatter(y, z, c=v, cmap=CMAP, norm=norm, s=s, edgecolors="0.5",
                       linewidths=0.3, plotnonfinite=True)
    cross = None
    if failing is not None and failing.any():
        cross = _crosses(ax, y[failing], z[failing])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("y (mm)")
    ax.set_ylabel("z (mm)")
    return m, cross


def _crosses(ax: Axes, y: Any, z: Any) -> Any:
    # line markers, not a scatter collection: one marker stamped per position
    return ax.plot(y, z, "x", ls="none", ms=math.sqrt(14), mew=0.8, color="k",
                   label="failing")[0]


# Figures of one layout drawn one after another (the residual maps of the
# heights, the fingerprints of the candidates): the figure drawn last in this
# process, kept to be drawn again with the next one's data (images, crosses,
# colour scale, title) instead of building its axes and their ticks anew, which
# is most of such a figure's time. name -> (signature, figure, handles); emptied
# when a figure fails, after each task of a worker and after each report.
_FRAMES: Dict[str, Tuple[Any, Figure, Any]] = {}


def _drop_frames(name: Optional[str] = None) -> None:
    """Close and forget the kept figure of that name (None: every one)."""
    for k in [k for k in _FRAMES if name in (None, k)]:
        plt.close(_FRAMES.pop(k)[1])


def _kept(name: str) -> Any:
    """(signature, figure, handles) kept under name by _keep, or None."""
    return _FRAMES.get(name)


def _keep(name: str, signature: Any, fig: Figure, handles: Any) -> None:
    _FRAMES[name] = (signature, fig, handles)


def _is_kept(fig: Figure) -> bool:
    return any(fig is fr[1] for fr in _FRAMES.values())


def _forget_frames() -> None:
    """Forget every kept figure without drawing it again (one was left half redrawn)."""
    _FRAMES.clear()


def _symnorm(*arrays: Any) -> Any:
    """Symmetric colour scale over all arrays: their largest |value|, unless a few
    outliers exceed 3x the 99th percentile; then the percentile, and the colour
    bar shows arrows (``norm.clipped``)."""
    vals = [np.abs(a[np.isfinite(a)]) for a in arrays if a is not None]
    vals = [v for v in vals if v.size]
    v = np.concatenate(vals) if vals else np.zeros(0)
    vmax = float(v.max()) if v.size else 0.0
    clipped = False
    if v.size >= 20:
        p99 = float(np.percentile(v, 99))
        if p99 > 0 and vmax > 3 * p99:
            vmax, clipped = p99, True
    if not vmax > 0:
        vmax = 1e-3
    norm = Normalize(-vmax, vmax)
    norm.clipped = clipped  # type: ignore[attr-defined]  # read back by _colorbar
    return norm


def _colorbar(fig: Figure, mappable: Any, cax: Axes, norm: Any, label: Optional[str]) -> None:
    fig.colorbar(mappable, cax=cax, label=label,
                 extend="both" if getattr(norm, "clipped", False) else "neither")


def _map_grid(figsize: Tuple[float, float], nrows: int, groups: Any) -> Any:
    """A figure of map panels: nrows x sum(groups) axes sharing y and z, and in each
    row a colour-bar axes after each group of maps. Returns (fig, maps, cbars).

    The layout is fixed here in inches rather than by matplotlib's constrained
    layout, which measured every tick label of these many panels twice per
    figure and so doubled their drawing time. Labels are kept on the outer
    panels only (left column, bottom row), as label_outer() does.
    """
    W, H = figsize
    left, right, bottom, top = 0.75, 0.1, 0.55, 0.55  # tick labels + axis label; suptitle
    title, vgap, gap = 0.3, 0.12, 0.15  # panel title above each row; between maps
    cb_pad, cb_w, cb_text = 0.12, 0.18, 0.85  # colour bar, its tick labels and label
    nmaps = sum(groups)
    mw = (W - left - right - len(groups) * (cb_pad + cb_w + cb_text)
          - (nmaps - len(groups)) * gap) / nmaps
    rh = (H - top - bottom - nrows * title - (nrows - 1) * vgap) / nrows
    fig = plt.figure(figsize=figsize)
    maps = np.empty((nrows, nmaps), dtype=object)
    cbars = np.empty((nrows, len(groups)), dtype=object)
    first = None
    for k in range(nrows):
        y0 = H - top - (k + 1) * (title + rh) - k * vgap
        x, j = left, 0
        for g, n in enumerate(groups):
            for i in range(n):
                ax = fig.add_axes((x / W, y0 / H, mw / W, rh / H), sharex=first, sharey=first)
                first = first or ax
                maps[k, j] = ax
                if k < nrows - 1:
                    ax.tick_params(labelbottom=False)
                if j > 0:
                    ax.tick_params(labelleft=False)
                j += 1
                x += mw + (gap if i < n - 1 else 0.0)
            cbars[k, g] = fig.add_axes(((x + cb_pad) / W, (y0 + 0.05 * rh) / H,
                                        cb_w / W, 0.9 * rh / H))
            x += cb_pad + cb_w + cb_text
    return fig, maps, cbars


def _fit(fig: Figure, axs: Any, right: float = 0.15, left_min: float = 0.0, wgap_min: float = 0.0) -> None:
    """Place a grid of equal axes (2-D array, as plt.subplots(squeeze=False)) with
    margins and gaps in inches fitted to their tick labels, axis labels and titles.

    What constrained layout does for these simple grids, measuring only those
    texts once instead of every artist's extent twice before the real drawing;
    it was a fifth of a single-panel figure's time. left_min: room for tick
    labels that reach left of the axes (rotated ones); wgap_min: between
    columns, for texts that reach right of an axes.
    """
    r = _agg(fig).get_renderer()
    dpi = fig.dpi
    W, H = fig.get_size_inches()
    nrows, ncols = axs.shape

    def ext(texts: Any, dim: str) -> float:
        sizes = [getattr(t.get_window_extent(r), dim) for t in texts
                 if t.get_visible() and t.get_text()]
        return float(max(sizes, default=0.0)) / dpi

    def label(t: Any, dim: str) -> float:  # an axis label or title and its padding
        return ext([t], dim) + 0.08 if t.get_visible() and t.get_text() else 0.0

    tick = 0.1  # tick length and pad
    cols = [max(ext(a.get_yticklabels(which="both"), "width") + label(a.yaxis.label, "width")
                for a in axs[:, j]) + tick for j in range(ncols)]
    rows = [max(ext(a.get_xticklabels(which="both"), "height") + label(a.xaxis.label, "height")
                for a in axs[k, :]) + tick for k in range(nrows)]
    titles = [max(label(a.title, "height") for a in axs[k, :]) for k in range(nrows)]
    sup = getattr(fig, "_suptitle", None)  # no public getter
    top = 0.12 + titles[0] + (label(sup, "height") if sup is not None else 0.0)
    left = max(cols[0], left_min) + 0.08
    bottom = rows[-1] + 0.08
    wgap = max(max(cols[1:], default=0.0), wgap_min) + 0.25
    hgap = max((rows[k] + titles[k + 1] for k in range(nrows - 1)), default=0.0) + 0.15
    aw = (W - left - right - (ncols - 1) * wgap) / ncols
    ah = (H - top - bottom - (nrows - 1) * hgap) / nrows
    fig.subplots_adjust(left=left / W, right=1 - right / W, bottom=bottom / H, top=1 - top / H,
                        wspace=wgap / aw, hspace=hgap / ah)


def _first_label_reach(ax: Axes) -> float:
    """How far (inches) the first x tick label, right-aligned at its tick and
    rotated, may reach left of the axes: at most its own width."""
    labels = [t for t in ax.get_xticklabels() if t.get_text()]
    if not labels:
        return 0.0
    fig: Any = ax.get_figure()
    return float(labels[0].get_window_extent(_agg(fig).get_renderer()).width / fig.dpi)


def _outer_labels(maps: Any) -> None:
    """Axis labels on the left column and the bottom row only."""
    nrows, ncols = maps.shape
    for k in range(nrows):
        for j in range(ncols):
            if k < nrows - 1:
                maps[k, j].set_xlabel("")
            if j > 0:
                maps[k, j].set_ylabel("")


# Titles sit at the top of their axes (axes.titley 1.0, matplotlib's own place
# when no tick labels are on top, as in every figure here): without it matplotlib
# measures every axes' y tick labels again for each title to see whether they
# reach up to it (a sixth of the drawing time in a profile).
_RC = {"axes.titley": 1.0, "figure.dpi": DPI}


def _agg(fig: Figure) -> Any:
    """fig's Agg canvas (pyplot's under the Agg backend this module selects; a new
    one if a caller's process had another backend forced)."""
    return fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)


def _save_png(fig: Figure, path: str) -> None:
    """Render fig and write it as an RGB PNG at zlib level 3.

    savefig would write RGBA (an alpha channel that is opaque everywhere here)
    at level 6: the same pixels, about twice the encoding time, 10 % larger files.
    """
    canvas = _agg(fig)
    canvas.draw()
    w, h = canvas.get_width_height(physical=True)
    img = PIL.Image.frombuffer("RGBA", (w, h), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    img.convert("RGB").save(path, format="png", compress_level=3, dpi=(DPI, DPI))


def _dots(ax: Axes, x: Any, y: Any, s: Any, color: Any, alpha: float, label: Optional[str] = None) -> None:
    """A plain scatter of equal dots (s: area in points², as scatter's) drawn as line
    markers: one marker image stamped at every point, several times faster than a
    scatter collection for the thousands of positions of a jig."""
    ax.plot(x, y, "o", ls="none", ms=math.sqrt(s), mew=0, color=color, alpha=alpha,
            label=label)


def _binned(ax: Axes, x: Any, y: Any, color: Any = "k", bins: int = 24, label: Optional[str] = "binned mean",
            width: Optional[float] = None) -> None:
    """Mean of y in bins of x (per value when x takes few values)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 2 or x.min() == x.max():
        return
    u = np.unique(x)
    if len(u) <= bins and width is None:
        k = np.searchsorted(u, x)
        ax.plot(u, np.bincount(k, weights=y) / np.bincount(k), "-", color=color, lw=2,
                marker="o", ms=4, label=label)
        return
    if width is not None and width > 0:
        bins = int(min(400, max(bins, math.ceil((x.max() - x.min()) / width))))
    nb = bins
    e = np.linspace(x.min(), x.max(), nb + 1)
    k = np.clip(np.digitize(x, e) - 1, 0, nb - 1)
    cnt = np.bincount(k, minlength=nb)
    s = np.bincount(k, weights=y, minlength=nb)
    c = (e[:-1] + e[1:]) / 2
    good = cnt > 0
    ax.plot(c[good], s[good] / cnt[good], "-", color=color, lw=2, label=label)


def _annot(ax: Axes, texts: Any) -> None:
    if texts:
        ax.text(0.02, 0.98, "\n".join(texts), transform=ax.transAxes, va="top",
                fontsize=7.5, color="darkred",
                bbox=dict(boxstyle="round", fc="white", ec="darkred", alpha=0.85))
