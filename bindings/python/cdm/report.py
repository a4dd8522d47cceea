"""Figures and an HTML page for a ``cdm calib diagnose`` result.

The numbers come from the C library (``cdm calib diagnose ... --json DIAG.json``);
this module only draws them::

    python3 -m cdm.report [EARLIER.json ...] DIAG.json --out DIR
    python3 -m cdm.report DIAG.json --before EARLIER.json [--before ...] --out DIR
    python3 bindings/python/cdm/report.py ...        (same, without importing cdm)

Files are in chronological order: the LAST positional file is the diagnosis the
report is about; the others, and any --before files (which come first), are
earlier runs (e.g. the nominal diagnosis before an effect was added), shown in
an "error fell" comparison in that order. This is the order `cdm calib diagnose
--before B.json ... --report DIR` passes them in.

From Python: ``write_report([earlier, ..., current], "DIR")`` where each run is
a path or an already loaded diagnosis dict (lists or numpy arrays).

DIR receives PNG figures and ``index.html`` (relative image paths, inline CSS,
no JavaScript, no external resources). Everything is written to a temporary
directory inside DIR first and moved into place only when complete.

The figures are drawn in forked worker processes, one per processor this
process may use (CDM_REPORT_JOBS=N sets how many; 1 draws in this process, as
happens anyway where fork is missing or the caller runs other threads). A figure
that cannot be drawn becomes a note in its place.

Exit codes: 0 report written; 2 an input file is missing, does not parse or is
not a diagnosis (the message names the file); 1 the report could not be written.

Only numpy, matplotlib and the standard library are imported, so this runs
whatever state the rest of the package (the ctypes binding) is in.
"""

import os
import sys

if __name__ == "__main__" and not __package__:
    # Run as a script: do not let the package directory shadow stdlib modules.
    _here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != _here]

import argparse
import concurrent.futures
import html
import json
import math
import multiprocessing
import re
import shutil
import tempfile
import threading

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import PIL.Image  # noqa: E402  (matplotlib's own dependency)
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402

__all__ = ["DiagnosisError", "load_diagnosis", "write_report", "main"]

AXES = ("x", "y", "z")
CMAP = "RdBu_r"
DPI = 100
# Every figure this module writes starts with one of these; stale ones from an
# earlier report in the same DIR are removed when a new report is moved in.
FIGURE_PREFIXES = ("error_summary", "residual_map_", "residual_cut", "candidates",
                   "fingerprint_", "vs_cable_length", "vs_variables", "comparison", "search_path")


class DiagnosisError(Exception):
    """An input file that cannot be used; the message names the file."""


# --------------------------------------------------------------------------- input


def load_diagnosis(path):
    """Read and sanity-check one diagnosis JSON; raise DiagnosisError if unusable."""
    try:
        with open(path, "r", encoding="utf-8") as f:
            text = f.read()
    except OSError as e:
        raise DiagnosisError(f"{path}: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise DiagnosisError(f"{path}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise DiagnosisError(f"{path}: not valid JSON: {e.msg} at line {e.lineno} "
                             f"column {e.colno}") from None
    if not isinstance(d, dict):
        raise DiagnosisError(f"{path}: not a diagnosis: the top level is a JSON "
                             f"{type(d).__name__}, expected an object")
    tool = d.get("tool")
    if tool is not None and tool != "cdm calib diagnose":
        raise DiagnosisError(f"{path}: not a diagnosis: \"tool\" is {tool!r}, "
                             f"expected 'cdm calib diagnose'")
    if tool is None and not any(k in d for k in ("error_mm", "positions", "model")):
        raise DiagnosisError(f"{path}: not a diagnosis: none of \"tool\", \"model\", "
                             f"\"error_mm\", \"positions\" is present")
    return d


def _num(v):
    """A float, or nan for None / non-numbers / booleans."""
    if isinstance(v, bool) or v is None:
        return math.nan
    if isinstance(v, (int, float)):
        return float(v)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _finite(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _dict(d, key):
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, dict) else None


def _list(d, key):
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, list) else None


def _array(v, width=None):
    """Nested list -> float array (None -> nan); None if the shape is unusable."""
    if not isinstance(v, list):
        return None
    try:
        if width is None:
            a = np.array([_num(x) for x in v], dtype=float)
        else:
            rows = []
            for r in v:
                if isinstance(r, list) and len(r) == width:
                    rows.append([_num(x) for x in r])
                else:
                    rows.append([math.nan] * width)
            a = np.array(rows, dtype=float).reshape(len(rows), width)
    except (TypeError, ValueError):
        return None
    return a


def _label(diag):
    model = diag.get("model")
    if isinstance(model, list):
        return "nominal" if not model else " + ".join(str(m) for m in model)
    return "(model not given)"


# ------------------------------------------------------------------- formatting

def fmt_mm(v):
    """Millimetre statistics: 4 decimals as the seed's Table 1; 'n/a' if missing."""
    return f"{v:.4f}" if _finite(v) else "n/a"


def fmt_g(v, digits=6):
    return f"{v:.{digits}g}" if _finite(v) else "n/a"


def _e(s):
    return html.escape(str(s), quote=True)


class _Figure:
    """One figure of the page: ``draw()`` returns a matplotlib Figure.

    Sections describe their figures instead of drawing them, so that the
    drawing (nearly all of the report's time) can be spread over processes;
    the page keeps the figure's place, filled in once it is drawn or failed.
    ``weight`` is a rough cost (tenths of a second, measured), to start the
    heavy ones first. Figures of one ``group`` (the residual maps, the
    fingerprints) redraw one figure of their layout in a process (see _FRAMES),
    which costs ``build`` more the first time: they are drawn by as few
    processes as keeps the load even.
    """

    def __init__(self, name, draw, alt, caption, weight=1, group=None, build=0):
        self.name, self.draw, self.alt, self.caption = name, draw, alt, caption
        self.weight, self.group, self.build = weight, group, build
        self.error = None  # why it could not be drawn, or None


class Page:
    """Collects HTML sections and notes about what was missing."""

    def __init__(self):
        self.parts = []  # HTML strings and _Figure places, in page order
        self.notes = []
        self.toc = []  # section titles (already escaped HTML), in order
        self.figures = []

    def note(self, text):
        self.notes.append(text)

    def figure(self, name, draw, alt, caption, weight=1, group=None, build=0):
        f = _Figure(name, draw, alt, caption, weight, group, build)
        self.figures.append(f)
        self.parts.append(f)

    def add(self, s):
        # Section headings get an anchor for the table of contents.
        if s.startswith("<h2>") and s.endswith("</h2>"):
            self.toc.append(s[4:-5])
            s = f'<h2 id="s{len(self.toc)}">{s[4:-5]}</h2>'
        self.parts.append(s)


def _table(header, rows, cls=""):
    h = "".join(f"<th>{_e(c)}</th>" for c in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table class="{cls}"><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>'


def _img(name, alt, caption):
    return (f'<figure><img src="{_e(name)}" alt="{_e(alt)}">'
            f"<figcaption>{caption}</figcaption></figure>")


# ----------------------------------------------------------------- positions

class Positions:
    """The per-position arrays, checked for a common length P."""

    def __init__(self, diag, page):
        self.ok = False
        pos = _dict(diag, "positions")
        if pos is None:
            page.note("The diagnosis has no \"positions\" section: no maps, cuts, "
                      "fingerprints or residual-versus-variable plots.")
            return
        ref = _array(pos.get("ref"), 3)
        if ref is None or len(ref) == 0:
            page.note("\"positions.ref\" is missing or empty: no per-position figures.")
            return
        self.P = P = len(ref)
        self.ref = ref

        def get(key, width=None, required=False):
            a = _array(pos.get(key), width)
            if a is None:
                if key in pos:
                    page.note(f"\"positions.{key}\" has an unusable shape; ignored.")
                elif required:
                    page.note(f"\"positions.{key}\" is not in the diagnosis.")
                return None
            if len(a) != P:
                page.note(f"\"positions.{key}\" has {len(a)} entries, \"positions.ref\" "
                          f"has {P}; ignored.")
                return None
            return a

        h = get("height")
        self.height = h if h is not None else ref[:, 0].copy()
        self.residual = get("residual_mm", 3, required=True)
        self.nominal = get("nominal_residual_mm", 3, required=True)
        self.ellipsoid = get("ellipsoid_residual_mm", 3)
        self.sigma = get("sigma_mm", 3)
        f = pos.get("failing")
        if isinstance(f, list) and len(f) == P:
            self.failing = np.array([bool(x) if isinstance(x, bool) else False for x in f])
        else:
            if "failing" in pos:
                page.note("\"positions.failing\" does not match the positions; not marked.")
            self.failing = np.zeros(P, dtype=bool)
        self.lengths = get("lengths_mm", 4)
        self.length_residual = get("length_residual_mm", 4)
        self.angle = get("cable_angle_deg", 4)
        # Heights: group positions whose height agrees to 0.01 mm.
        hk = np.round(self.height, 2)
        self.heights = [float(v) for v in np.unique(hk[np.isfinite(hk)])]
        self.height_index = [np.flatnonzero(hk == v) for v in self.heights]
        if not self.heights:
            page.note("No finite heights in the positions; per-height figures skipped.")
            return
        if self.residual is None and self.nominal is None:
            page.note("Neither \"positions.residual_mm\" nor "
                      "\"positions.nominal_residual_mm\" is usable: no residual maps.")
        self.ok = True


def _regular_grid(y, z):
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


def _edges(c):
    if len(c) == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    p = c[1] - c[0]
    return np.concatenate([c - p / 2, [c[-1] + p / 2]])


def _raster(g, v):
    """Values v on the regular grid g (from _regular_grid), nan where no position."""
    yc, zc, iy, iz = g
    G = np.full((len(zc), len(yc)), np.nan)
    G[iz, iy] = v
    return np.ma.masked_invalid(G)


def _map(ax, y, z, v, norm, failing=None, g=None):
    """Draw values v at (y, z): raster on a regular grid (g, from _regular_grid(y, z)),
    scatter otherwise. Returns (mappable, the line of failing crosses or None)."""
    if g is not None:
        ey, ez = _edges(g[0]), _edges(g[1])
        m = ax.imshow(_raster(g, v), cmap=CMAP, norm=norm, origin="lower",
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


def _crosses(ax, y, z):
    # line markers, not a scatter collection: one marker stamped per position
    return ax.plot(y, z, "x", ls="none", ms=math.sqrt(14), mew=0.8, color="k",
                   label="failing")[0]


# Figures of one layout drawn one after another (the residual maps of the
# heights, the fingerprints of the candidates): the figure drawn last in this
# process, kept to be drawn again with the next one's data (images, crosses,
# colour scale, title) instead of building its axes and their ticks anew, which
# is most of such a figure's time. name -> (signature, figure, handles); emptied
# when a figure fails, after each task of a worker and after each report.
_FRAMES: dict = {}


def _drop_frames(name=None):
    """Close and forget the kept figure of that name (None: every one)."""
    for k in [k for k in _FRAMES if name in (None, k)]:
        plt.close(_FRAMES.pop(k)[1])


def _symnorm(*arrays):
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
    norm.clipped = clipped
    return norm


def _colorbar(fig, mappable, cax, norm, label):
    fig.colorbar(mappable, cax=cax, label=label,
                 extend="both" if getattr(norm, "clipped", False) else "neither")


def _map_grid(figsize, nrows, groups):
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


def _fit(fig, axs, right=0.15, left_min=0.0, wgap_min=0.0):
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

    def ext(texts, dim):
        sizes = [getattr(t.get_window_extent(r), dim) for t in texts
                 if t.get_visible() and t.get_text()]
        return max(sizes, default=0.0) / dpi

    def label(t, dim):  # an axis label or title and its padding
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


def _first_label_reach(ax):
    """How far (inches) the first x tick label, right-aligned at its tick and
    rotated, may reach left of the axes: at most its own width."""
    labels = [t for t in ax.get_xticklabels() if t.get_text()]
    if not labels:
        return 0.0
    fig = ax.get_figure()
    return labels[0].get_window_extent(_agg(fig).get_renderer()).width / fig.dpi


def _outer_labels(maps):
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


def _agg(fig):
    """fig's Agg canvas (pyplot's under the Agg backend this module selects; a new
    one if a caller's process had another backend forced)."""
    return fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)


def _save_png(fig, path):
    """Render fig and write it as an RGB PNG at zlib level 3.

    savefig would write RGBA (an alpha channel that is opaque everywhere here)
    at level 6: the same pixels, about twice the encoding time, 10 % larger files.
    """
    canvas = _agg(fig)
    canvas.draw()
    w, h = canvas.get_width_height(physical=True)
    img = PIL.Image.frombuffer("RGBA", (w, h), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    img.convert("RGB").save(path, format="png", compress_level=3, dpi=(DPI, DPI))


def _draw_one(f, tmp):
    """Draw one figure into tmp; None, or why it could not be drawn."""
    try:
        with matplotlib.rc_context(_RC):
            fig = f.draw()
            try:
                _save_png(fig, os.path.join(tmp, f.name))
            finally:
                if not any(fig is fr[1] for fr in _FRAMES.values()):
                    plt.close(fig)
    except Exception as e:  # one broken figure must not lose the rest of the report
        _FRAMES.clear()  # a figure left half redrawn
        plt.close("all")
        return f"{type(e).__name__}: {e}"
    return None


# The figures a pool's worker processes draw: set before the pool forks them, so
# that the workers inherit the drawing closures instead of receiving them pickled.
_PENDING = None


def _draw_pending(task):
    figures, tmp = _PENDING
    try:
        return [_draw_one(figures[i], tmp) for i in task]
    finally:
        _drop_frames()


def _tasks(figures, n):
    """The figures' indices in tasks for n processes, heaviest task first.

    A group's figures go into as few tasks (consecutive runs) as keep every
    task under an n-th of the total, since each task builds the group's figure
    once more; every other figure is a task of its own.
    """
    total = (sum(f.weight for f in figures)
             + sum({f.group: f.build for f in figures if f.group is not None}.values()))
    groups, tasks = {}, []
    for i, f in enumerate(figures):
        if f.group is None:
            tasks.append(([i], f.weight))
        else:
            groups.setdefault(f.group, []).append(i)
    for idx in groups.values():
        w = sum(figures[i].weight for i in idx)
        b = max(figures[i].build for i in idx)
        k = max(1, min(len(idx), math.ceil((w + b) / (total / n) - 1e-9)))
        for part in np.array_split(np.array(idx), k):
            tasks.append(([int(i) for i in part], sum(figures[i].weight for i in part) + b))
    tasks.sort(key=lambda t: -t[1])
    return [t for t, _ in tasks]


def _workers(n):
    """How many processes to draw n figures with (1: in this process).

    CDM_REPORT_JOBS sets it (1 draws everything in this process). Worker
    processes are forked, so only where fork exists, and only when this process
    runs no other thread (a fork copies no thread but may copy a held lock).
    """
    env = os.environ.get("CDM_REPORT_JOBS", "").strip()
    if env:
        try:
            want = max(1, int(env))
        except ValueError:
            raise DiagnosisError(f"CDM_REPORT_JOBS={env!r}: not a whole number of processes") from None
    else:
        try:
            want = len(os.sched_getaffinity(0))
        except (AttributeError, OSError):
            want = os.cpu_count() or 1
    if ("fork" not in multiprocessing.get_all_start_methods()
            or threading.active_count() > 1
            # run under another name (e.g. loaded from a file): a worker could not find _draw_pending
            or getattr(sys.modules.get(__name__), "_draw_pending", None) is not _draw_pending):
        return 1
    return max(1, min(want, n))


def _draw_all(figures, tmp):
    """Draw every figure into tmp, in worker processes when that helps; sets .error."""
    global _PENDING
    n = _workers(len(figures))
    if n <= 1:
        try:
            for f in figures:
                f.error = _draw_one(f, tmp)
        finally:
            _drop_frames()
        return
    # Heaviest first, so that no long task starts last and leaves a core idle.
    _PENDING = (figures, tmp)
    try:
        with concurrent.futures.ProcessPoolExecutor(
                n, mp_context=multiprocessing.get_context("fork")) as ex:
            futures = [(task, ex.submit(_draw_pending, task)) for task in _tasks(figures, n)]
            for task, fut in futures:
                try:
                    for i, error in zip(task, fut.result()):
                        figures[i].error = error
                except Exception as e:  # e.g. a worker killed: its figures are lost, not the page
                    for i in task:
                        figures[i].error = f"the drawing process failed ({type(e).__name__}: {e})"
    finally:
        _PENDING = None


# --------------------------------------------------------------------- sections

STAT_ROWS = (("nominal_error_mm", "Nominal model"),
             ("ellipsoid_error_mm", "Seed's ellipsoid (eq. 4-5)"),
             ("error_mm", "Current model"),
             ("noise_floor_mm", "Noise floor (repeatability + jig tolerance)"))


def _stat_cells(block):
    cells = []
    for a in AXES:
        s = _dict(block, a) or {}
        mean, std = s.get("mean"), s.get("std")
        cells.append(f"{fmt_mm(mean)} ± {fmt_mm(std)}")
        cells.append(fmt_mm(s.get("rms")))
        cells.append(fmt_mm(s.get("max")))
    return cells


def _glitch_words(g):
    """The samples the dataset's screen set aside, for the Data line ('' when none)."""
    if not isinstance(g, dict) or not _finite(g.get("count")) or g["count"] <= 0:
        return ""
    return (f"; {int(g['count'])} samples at {fmt_g(g.get('positions'))} positions set aside as "
            f"glitches (beyond {fmt_g(g.get('threshold_sd'), 3)} sd of their position's median)")


def _outlier_words(o):
    """The positions the diagnosis set aside as outliers, for the Data line ('' when none)."""
    if not isinstance(o, dict) or not _finite(o.get("count")) or o["count"] <= 0:
        return ""
    sa = o.get("set_aside")
    pts = [str(x.get("point")) for x in (sa if isinstance(sa, list) else []) if isinstance(x, dict)][:8]
    return (f"; {int(o['count'])} of {fmt_g(o.get('positions_read'))} positions set aside as outliers "
            f"(points {_e(', '.join(pts))}{', ...' if o['count'] > 8 else ''})")


def section_summary(diag, page):
    page.add("<h2>1. Summary</h2>")
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

    # Scalar facts.
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
    jt = _dict(diag, "jig_tolerance_mm")
    if jt is not None:
        pa = jt.get("per_axis")
        pa = (" per axis " + ", ".join(f"{a} {fmt_mm(_num(v))}" for a, v in zip(AXES, pa))
              if isinstance(pa, list) and len(pa) == 3 else "")
        ph = jt.get("plate_holes")
        ph = (f"; of it shared by a hole at every height (weighed as one block per hole): "
              + ", ".join(f"{a} {fmt_mm(_num(v))}" for a, v in zip(AXES, ph))
              if isinstance(ph, list) and len(ph) == 3 and any(_finite(v) and _num(v) > 0 for v in ph) else "")
        facts.append(("Jig tolerance", f"{fmt_mm(jt.get('value'))} mm "
                      f"({_e(jt.get('source', 'source not given'))}){pa}{ph}"))
    fit = _dict(diag, "fit")
    if fit is not None:
        conv = fit.get("converged")
        facts.append(("Fit", f"{_e(fit.get('algorithm', '?'))}, "
                      f"{fmt_g(fit.get('evaluations'))} evaluations, "
                      f"{fmt_g(fit.get('seconds'), 3)} s, "
                      + ("converged" if conv is True else
                         "<span class=\"bad\">NOT converged</span>" if conv is False else
                         "convergence not given")
                      + (f"; {fmt_g(fit['free_parameters'])} free parameters"
                         if _finite(fit.get("free_parameters")) else "")
                      + (f"; {_e(fit['message'])}" if isinstance(fit.get("message"), str)
                         and fit["message"] else "")))
    jig = _dict(diag, "jig")
    if jig is not None:
        # The jig's own errors (plate holes, fixture heights), named as the
        # jig's by the diagnosis and taken out of its tests.
        texts = [t for t in (jig.get("text") or []) if isinstance(t, str)]
        holes = jig.get("holes") if isinstance(jig.get("holes"), dict) else {}
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
        hs = data.get("heights")
        hs = ", ".join(fmt_g(_num(h), 6) for h in hs) if isinstance(hs, list) else "n/a"
        ign = data.get("ignored_columns")
        facts.append(("Data", f"{_e(data.get('path', '?'))}: {fmt_g(data.get('rows'))} rows, "
                      f"{fmt_g(data.get('positions'))} positions, heights {hs} mm"
                      + (f"; ignored columns: {_e(', '.join(map(str, ign)))}"
                         if isinstance(ign, list) and ign else "")
                      + (f"; {int(data['out_of_workspace_samples'])} samples out of the "
                         f"workspace" if _finite(data.get("out_of_workspace_samples"))
                         and data["out_of_workspace_samples"] > 0 else "")
                      + _glitch_words(data.get("glitches"))
                      + _outlier_words(data.get("outliers"))))
    dev = _dict(diag, "device")
    if dev is not None:
        facts.append(("Device (mm)", ", ".join(
            f"{k[0]} = {fmt_g(dev.get(k), 6)}" for k in ("a_mm", "b_mm", "m_mm"))))
    if isinstance(diag.get("version"), str):
        facts.append(("Produced by", _e(f"{diag.get('tool', '?')} {diag['version']}")
                      + (f" in {fmt_g(diag['seconds'], 3)} s" if _finite(diag.get("seconds"))
                         else "")))
    page.add(_table(["", ""], [[f"<b>{_e(k)}</b>", v] for k, v in facts], "facts"))

    # Fitted parameters.
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

    # Validation.
    val = _dict(diag, "validation")
    if val is not None:
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
        r = _dict(val, "in_sample_rms_mm")
        if r is not None:
            vrows.append(["in sample (fitted on all heights)"] + [fmt_mm(r.get(a)) for a in AXES])
        page.add(_table(["fold", "x RMS (mm)", "y RMS (mm)", "z RMS (mm)"], vrows, "stats"))
        page.add("<p>Held-out error well above the in-sample error means the added effect "
                 "fits noise or one height's peculiarity rather than the device.</p>")
    else:
        page.add("<p>No cross-validation in the diagnosis (it needs fitted parameters and "
                 "more than one height).</p>")

    # A bar chart of the four RMS rows.
    blocks = [(name, _dict(diag, key)) for key, name in STAT_ROWS]
    blocks = [(n, b) for n, b in blocks if b is not None]
    if blocks:
        def draw():
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


def section_maps(diag, page, P):
    page.add("<h2>2. Residual maps per height</h2>")
    if not P.ok or (P.residual is None and P.nominal is None):
        page.add("<p>Not available (see the notes).</p>")
        return
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
    cols = [c for c in cols if c[0] is not None]
    norms = [_symnorm(*[c[0][:, k] for c in cols]) for k in range(3)]
    # The current residual again on its own scale when the shared one washes it out,
    # so that what is left (the next missing effect) is visible.
    cur = next((c[0] for c in cols if c[2]), None)
    zoom = [None] * 3
    if cur is not None and len(cols) > 1:
        for k in range(3):
            nk = _symnorm(cur[:, k])
            if nk.vmax < norms[k].vmax / 3:
                zoom[k] = nk
    ncol = len(cols) + (1 if any(zoom) else 0)
    groups = [len(cols)] + ([1] if ncol > len(cols) else [])
    # The panels: (row, column, values over all positions, norm, crosses marked).
    panels = []
    for k in range(3):
        for j, (arr, title, current) in enumerate(cols):
            panels.append((k, j, arr[:, k], norms[k], current))
        if ncol > len(cols) and zoom[k] is not None:
            panels.append((k, ncol - 1, cur[:, k], zoom[k], True))
    # Same layout at every height on the same grid: a process redraws its last figure.
    signature = (ncol, tuple(cols[j][1] for j in range(len(cols))))

    def suptitle(h, idx):
        nf = int(P.failing[idx].sum())
        return (f"Residual (estimate - reference) at height x = {h:g} mm"
                + (f"; {nf} failing positions marked ×" if nf else ""))

    def redraw(h, idx, g):
        """The last figure drawn, with this height's data, or None if it cannot be."""
        last = _FRAMES.get("residual_map")
        if g is None or last is None or last[0] != (signature, g[0].tobytes(), g[1].tobytes()):
            return None
        _, fig, handles = last
        y, z = P.ref[idx, 1], P.ref[idx, 2]
        fail = P.failing[idx]
        for i, ((k, j, vals, norm, marked), (im, cross)) in enumerate(zip(panels, handles)):
            im.set_data(_raster(g, vals[idx]))
            if marked:
                if cross is None and fail.any():
                    handles[i] = (im, _crosses(im.axes, y[fail], z[fail]))
                elif cross is not None:
                    cross.set_data(y[fail], z[fail])
        fig.suptitle(suptitle(h, idx))
        return fig

    for h, idx in zip(P.heights, P.height_index):
        def draw(h=h, idx=idx):
            y, z = P.ref[idx, 1], P.ref[idx, 2]
            g = _regular_grid(y, z)
            fig = redraw(h, idx, g)
            if fig is not None:
                return fig
            _drop_frames("residual_map")
            fig, axs, cbs = _map_grid((4.0 * ncol + 1.6 * (ncol - len(cols) + 1), 11), 3, groups)
            handles = []
            for k, j, vals, norm, marked in panels:
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
                if ncol > len(cols) and zoom[k] is None:
                    ax = axs[k, -1]
                    ax.set_axis_off()
                    cbs[k, 1].remove()
                    ax.text(0.5, 0.5, "current residual:\nsee the shared scale", ha="center",
                            va="center", transform=ax.transAxes, fontsize=9, color="0.4")
            _outer_labels(axs)
            fig.suptitle(suptitle(h, idx))
            if g is not None:
                _FRAMES["residual_map"] = ((signature, g[0].tobytes(), g[1].tobytes()), fig, handles)
            return fig
        page.figure(f"residual_map_h{h:g}.png".replace("-", "m"), draw, f"residual maps at {h:g} mm",
                    f"Height {h:g} mm: residual per jig position in the cable plane "
                    f"(y right, z up), rows x, y, z; {_e(how)}"
                    + (", and the current residual again on its own colour scale"
                       if ncol > len(cols) else "")
                    + ". One symmetric colour scale per axis for all "
                    f"heights (arrows on a colour bar: a few outliers beyond it are "
                    f"drawn at its ends); black crosses mark positions whose mean residual "
                    f"is beyond what noise and jig tolerance explain.", weight=ncol,
                    group="residual_map", build=2)
    if len(P.heights) == 1:
        page.note("Only one height in the data: the x error cannot be separated from a "
                  "height-dependent effect.")
    section_cut(page, P, *cut)


def _cut(P, idx, along):
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


def section_cut(page, P, solid, solid_name, dashed, dashed_name):
    # The grid lines first: whether there is a cut decides between figure and note.
    cuts = {(along, i): _cut(P, idx, along)
            for along in (1, 2) for i, idx in enumerate(P.height_index)}
    if all(r is None for r in cuts.values()):
        page.note("No grid line through the centre: cut view skipped.")
        return

    def draw():
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


def _fmt_list(v):
    return ", ".join(str(x) for x in v) if isinstance(v, list) and v else ""


def section_candidates(diag, page):
    page.add("<h2>3. Which effect is missing: candidate ranking</h2>")
    cands = _list(diag, "candidates")
    if cands is None:
        page.note("\"candidates\" is not in the diagnosis: no ranking.")
        page.add("<p>Not available.</p>")
        return
    cands = [c for c in cands if isinstance(c, dict)]
    if not cands:
        page.add("<p>No candidate effects were scored (every catalogued effect is in "
                 "the model, or none applies).</p>")
    else:
        metric = None
        for key, label in (("bic_change", "BIC change (negative = better)"),
                           ("score", "score"), ("delta_chi2", "Δχ² when fitted")):
            if any(_finite(c.get(key)) for c in cands):
                metric = (key, label)
                break
        if metric is not None:
            key, label = metric
            names = [str(c.get("effect", "?")) for c in cands]
            vals = np.array([_num(c.get(key)) for c in cands])
            # one colour per confused set
            groups, colours = {}, []
            pal = plt.get_cmap("tab10")
            for c in cands:
                cw = c.get("confused_with")
                cw = cw if isinstance(cw, list) else []
                s = frozenset([str(c.get("effect"))] + [str(x) for x in cw])
                gk = next((g for g in groups if g & s), None)
                if gk is None:
                    groups[s] = len(groups)
                    gk = s
                colours.append(pal(groups[gk] % 10) if len(s) > 1 else "0.55")
            # Right panel: the x RMS each candidate leaves, on a log scale
            # against the current model's and the noise floor. With a large
            # residual every candidate removes most of the chi-square and the
            # BIC bars look alike; what is left is what tells them apart.
            after_x = np.array([_num((_dict(_dict(c, "error_mm_after") or {}, "x") or {}).get("rms"))
                                for c in cands])
            show_after = np.isfinite(after_x).any() and np.nanmin(after_x) > 0
            def draw():
                fig, axs = plt.subplots(1, 2 if show_after else 1, figsize=(13 if show_after else 8.5,
                                        0.45 * len(cands) + 1.6), squeeze=False)
                ax = axs[0][0]
                yy = np.arange(len(cands))
                if show_after:
                    ax2 = axs[0][1]
                    ax2.barh(yy, np.where(np.isfinite(after_x), after_x, np.nan), color=colours)
                    ax2.set_xscale("log")
                    ax2.set_yticks(yy, [""] * len(cands))
                    ax2.invert_yaxis()
                    cur = _num((_dict(_dict(diag, "error_mm") or {}, "x") or {}).get("rms"))
                    floor = _num((_dict(_dict(diag, "noise_floor_mm") or {}, "x") or {}).get("rms"))
                    if np.isfinite(cur) and cur > 0:
                        ax2.axvline(cur, color="tab:red", lw=1.2, label=f"current model {cur:.3f} mm")
                    if np.isfinite(floor) and floor > 0:
                        ax2.axvline(floor, color="k", ls="--", lw=1.2, label=f"noise floor {floor:.3f} mm")
                    ax2.set_xlabel("x RMS error with the effect added (mm, log)")
                    ax2.set_title("What each candidate leaves")
                    ax2.legend(loc="lower right", fontsize=8)
                    ax2.grid(axis="x", alpha=0.3, which="both")
                ax.barh(yy, np.nan_to_num(vals), color=colours)
                ax.set_yticks(yy, names)
                ax.invert_yaxis()
                ax.axvline(0, color="k", lw=0.8)
                ax.set_xlabel(label)
                ax.set_title("Candidate effects, best first")
                span = np.nanmax(np.abs(vals)) if np.isfinite(vals).any() else 1.0
                notes = []  # they may reach right of the axes: the gap keeps room
                for i, c in enumerate(cands):
                    t = _fmt_list(c.get("confused_with"))
                    txt = ("n/a" if not np.isfinite(vals[i]) else "") + \
                          (f"  ≈ {t}" if t else "")
                    if txt:
                        x0 = vals[i] if np.isfinite(vals[i]) and vals[i] > 0 else 0.0
                        notes.append(ax.text(x0 + 0.01 * span, i, txt, va="center", fontsize=8,
                                             color="0.15"))
                ax.grid(axis="x", alpha=0.3)
                r = _agg(fig).get_renderer()
                gap = max((t.get_window_extent(r).width / fig.dpi for t in notes), default=0.0)
                _fit(fig, axs, wgap_min=gap)
                if notes and not show_after:
                    # One column: the notes beside the longest bars reach
                    # past the axes into the right margin, which must hold them.
                    edge = ax.get_window_extent(r).x1
                    over = max((t.get_window_extent(r).x1 - edge) / fig.dpi for t in notes)
                    if over > 0:
                        _fit(fig, axs, right=0.15 + over, wgap_min=gap)
                return fig
            page.figure("candidates.png", draw, "candidate ranking",
                        f"Each catalogued effect not in the model, fitted on top of it, "
                        f"ranked by {label}. Bars of one colour (and '≈' names) are "
                        f"effects the data cannot tell apart. Right: the x RMS error "
                        f"left with each one added; the right effect reaches the noise floor.",
                        weight=2)
        rows = []
        for c in cands:
            after = _dict(c, "error_mm_after") or {}
            rows.append([_e(c.get("effect", "?")), fmt_g(c.get("score"), 4),
                         fmt_g(c.get("delta_chi2"), 5), fmt_g(c.get("bic_change"), 5),
                         fmt_g(c.get("n_params")),
                         *[fmt_mm((_dict(after, a) or {}).get("rms")) for a in AXES],
                         fmt_g(c.get("residual_correlation"), 3),
                         {True: "yes", False: "no"}.get(c.get("explained_after"), "n/a"),
                         _e(_fmt_list(c.get("confused_with")))])
        page.add(_table(["effect", "score", "Δχ²", "BIC change", "params",
                         "x RMS after (mm)", "y RMS after (mm)", "z RMS after (mm)",
                         "corr. with residual", "explained after", "confused with"],
                        rows, "cands"))
    ins = _list(diag, "inseparable")
    if ins:
        page.add("<h3>Inseparable effects</h3><ul>")
        for s in ins:
            if isinstance(s, dict):
                page.add(f"<li><b>{_e(_fmt_list(s.get('effects')))}</b>: "
                         f"{_e(s.get('separate_by', 'no separating measurement given'))}</li>")
        page.add("</ul>")


def section_search(diag, page):
    page.add("<h2>3b. The model search: where following the ranking leads</h2>")
    rec = _dict(diag, "recommended")
    if rec is None:
        why = diag.get("search") if isinstance(diag.get("search"), str) else "not in the diagnosis"
        page.add(f"<p>No model search ({_e(why)}).</p>")
        return
    effects = [str(e) for e in (_list(rec, "effects") or [])]
    name = " + ".join(effects) if effects else "the nominal model"
    state = ("explains the data" if rec.get("explained") is True else
             "explains the data to within what matters" if rec.get("negligible_only") is True else
             "does not explain the data")
    xr = _num((_dict(_dict(rec, "error_mm") or {}, "x") or {}).get("rms"))
    nf = _list(rec, "noise_floor_mm") or []
    nfx = _num(nf[0]) if nf else float("nan")
    page.add(f"<p><b>Recommended model: {_e(name)}</b>: {_e(state)}; x RMS {fmt_mm(xr)} mm at the "
             f"noise floor {fmt_mm(nfx)} mm.</p>")
    path = [st for st in (_list(rec, "path") or []) if isinstance(st, dict)]
    if path:
        rows = []
        for st in path:
            a, r = st.get("added"), st.get("removed")
            move = (f"{_e(r)} → {_e(a)}" if a and r else f"+ {_e(a)}" if a else f"− {_e(r)}")
            rows.append([_e(st.get("step")), move, _e(fmt_g(_num(st.get("bic_change")), 4)),
                         fmt_mm(_num(st.get("x_rms_mm")))])
        page.add(_table(["step", "move", "BIC change", "x RMS after (mm)"], rows))
        xs = np.array([_num(st.get("x_rms_mm")) for st in path])
        if np.isfinite(xs).all() and (xs > 0).all():
            start = _num((_dict(_dict(diag, "error_mm") or {}, "x") or {}).get("rms"))
            ys = np.concatenate([[start], xs]) if np.isfinite(start) and start > 0 else xs
            labels = (["start"] if len(ys) > len(xs) else []) + [
                ("+" + str(st.get("added")) if not st.get("removed") else
                 "−" + str(st.get("removed")) if not st.get("added") else
                 str(st.get("removed")) + "→" + str(st.get("added"))) for st in path]
            def draw():
                fig, ax = plt.subplots(figsize=(8.5, 3.2))
                ax.plot(np.arange(len(ys)), ys, "o-", color="tab:blue")
                ax.set_yscale("log")
                ax.set_xticks(np.arange(len(ys)), labels, rotation=25, ha="right", fontsize=8)
                if np.isfinite(nfx) and nfx > 0:
                    ax.axhline(nfx, color="0.4", ls="--", lw=1, label=f"noise floor {nfx:.3f} mm")
                    ax.legend(fontsize=8)
                ax.set_ylabel("x RMS (mm)")
                ax.set_title("x error along the search path")
                _fit(fig, np.array([[ax]]), left_min=_first_label_reach(ax))
                return fig
            page.figure("search_path.png", draw, "x error along the search path",
                        "Each step of the search and the x error it leaves (log scale).")
    else:
        page.add("<p>The search made no move: no addition, removal or swap lowers the criterion.</p>")
    alts = [a for a in (_list(rec, "alternatives") or []) if isinstance(a, list)]
    dbic = _list(rec, "alternatives_bic_change") or []
    if alts:
        items = "".join(
            f"<li>{_e(' + '.join(str(x) for x in a) or 'the nominal model')} (BIC "
            f"{_e(fmt_g(_num(dbic[i]) if i < len(dbic) else float('nan'), 3))})</li>"
            for i, a in enumerate(alts))
        page.add(f"<p>Models the data cannot tell from it (BIC within 10):</p><ul>{items}</ul>")
    left = [x for x in (_list(rec, "significant_left") or []) if isinstance(x, dict)]
    if left:
        items = "".join(
            f"<li>{_e(x.get('effect') or x.get('text'))}"
            f"{' (negligible: under a tenth of the noise floor)' if x.get('negligible') else ''}</li>"
            for x in left)
        page.add(f"<p>Still significant on top of it:</p><ul>{items}</ul>")
    if isinstance(rec.get("criterion"), str):
        page.add(f"<p class=\"small\">Criterion: {_e(rec['criterion'])}.</p>")


def _corr(a, b):
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return math.nan
    a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
    d = math.sqrt(float((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / d) if d > 0 else math.nan


def section_fingerprints(diag, page, P):
    page.add("<h2>4. Fingerprints of the top candidates</h2>")
    fps = _dict(diag, "fingerprints")
    if fps is None:
        page.note("\"fingerprints\" is not in the diagnosis.")
        page.add("<p>Not available.</p>")
        return
    if not P.ok or P.residual is None:
        page.add("<p>Not available: no per-position residual.</p>")
        return
    order = [str(c.get("effect")) for c in (_list(diag, "candidates") or [])
             if isinstance(c, dict) and str(c.get("effect")) in fps]
    order += [k for k in fps if k not in order]
    cand_by = {str(c.get("effect")): c for c in (_list(diag, "candidates") or [])
               if isinstance(c, dict)}
    hsel = list(range(len(P.heights)))
    if len(hsel) > 5:
        hsel = sorted(set(np.linspace(0, len(hsel) - 1, 5).round().astype(int).tolist()))
    n = 0
    for eff in order:
        if n >= 4:
            break
        fp = _array(fps[eff], 3)
        if fp is None or len(fp) != P.P:
            page.note(f"Fingerprint of {eff} does not match the positions; skipped.")
            continue
        n += 1
        cx = _corr(fp[:, 0], P.residual[:, 0])
        c3 = _corr(fp.ravel(), P.residual.ravel())
        cj = cand_by.get(eff, {}).get("residual_correlation")
        title = f"{eff}: corr(x) = {fmt_g(cx, 3)}, corr(x,y,z) = {fmt_g(c3, 3)}"
        if _finite(cj):
            title += f", reported correlation = {fmt_g(cj, 3)}"

        def draw(fp=fp, title=title):
            nf = _symnorm(fp[:, 0])
            grids = [_regular_grid(P.ref[P.height_index[hi], 1], P.ref[P.height_index[hi], 2])
                     for hi in hsel]
            # Every candidate's figure has the same layout and bottom row: a process
            # redraws its last one with this one's top row (values, colour scale) and title.
            sig = (None if any(g is None for g in grids) else
                   (nf.clipped,) + tuple(g[0].tobytes() + g[1].tobytes() for g in grids))
            last = _FRAMES.get("fingerprint")
            if sig is not None and last is not None and last[0] == sig:
                _, fig, top = last
                for im, g, hi in zip(top, grids, hsel):
                    im.set_data(_raster(g, fp[P.height_index[hi], 0]))
                    im.set_norm(nf)  # the colour bar follows its image's norm
                fig.suptitle(title)
                return fig
            _drop_frames("fingerprint")
            nr = _symnorm(P.residual[:, 0])
            fig, axs, cbs = _map_grid((3.3 * len(hsel) + 1.3, 6.8), 2, [len(hsel)])
            top = []
            for j, (hi, g) in enumerate(zip(hsel, grids)):
                idx = P.height_index[hi]
                y, z = P.ref[idx, 1], P.ref[idx, 2]
                m0, _ = _map(axs[0, j], y, z, fp[idx, 0], nf, g=g)
                top.append(m0)
                axs[0, j].set_title(f"fingerprint x, {P.heights[hi]:g} mm", fontsize=9)
                m1, _ = _map(axs[1, j], y, z, P.residual[idx, 0], nr, g=g)
                axs[1, j].set_title(f"current residual x, {P.heights[hi]:g} mm", fontsize=9)
            _colorbar(fig, m0, cbs[0, 0], nf, "x shift by the effect (mm)")
            _colorbar(fig, m1, cbs[1, 0], nr, "x residual (mm)")
            _outer_labels(axs)
            fig.suptitle(title)
            if sig is not None:
                _FRAMES["fingerprint"] = (sig, fig, top)
            return fig
        safe = re.sub(r"[^A-Za-z0-9_.-]", "_", eff)
        page.figure(f"fingerprint_{n}_{safe}.png", draw, f"fingerprint of {eff}",
                    f"<b>{_e(eff)}</b>: top row, how the effect at its fitted size moves "
                    f"the x estimate; bottom row, the current x residual (own colour "
                    f"scales). The right effect has the same pattern (correlation near "
                    f"±1 and similar size). Correlation over all positions: x "
                    f"{fmt_g(cx, 3)}, all axes {fmt_g(c3, 3)}"
                    + (f"; reported by the diagnosis {fmt_g(cj, 3)}" if _finite(cj) else "")
                    + ".", weight=len(hsel) // 2, group="fingerprint", build=2)
    if n == 0:
        page.add("<p>No usable fingerprints.</p>")


_VARIABLE_KINDS = ("height", "radius", "length", "angle")


def _finding_target(f):
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


def _finding_target_from_name(var):
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


def _dots(ax, x, y, s, color, alpha, label=None):
    """A plain scatter of equal dots (s: area in points², as scatter's) drawn as line
    markers: one marker image stamped at every point, several times faster than a
    scatter collection for the thousands of positions of a jig."""
    ax.plot(x, y, "o", ls="none", ms=math.sqrt(s), mew=0, color=color, alpha=alpha,
            label=label)


def _binned(ax, x, y, color="k", bins=24, label="binned mean", width=None):
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


def _annot(ax, texts):
    if texts:
        ax.text(0.02, 0.98, "\n".join(texts), transform=ax.transAxes, va="top",
                fontsize=7.5, color="darkred",
                bbox=dict(boxstyle="round", fc="white", ec="darkred", alpha=0.85))


def _finding_text(f):
    t = f.get("text")
    if isinstance(t, str) and t:
        return t if len(t) <= 70 else t[:67] + "..."
    s = f"{f.get('kind', '?')} in {f.get('axis', '?')}"
    if _finite(f.get("period_mm")):
        s += f", period {fmt_g(f['period_mm'], 4)} mm"
    if _finite(f.get("amplitude_mm")):
        s += f", amplitude {fmt_g(f['amplitude_mm'], 3)} mm"
    return s


def _route_findings(findings):
    """Route each finding to the panel it is about.

    Returns (pos_notes, len_notes, periods): position-residual findings (axis x, y
    or z) keyed by (variable kind, axis index) for vs_variables.png; cable-reading
    findings keyed by cable (1..4, None = all cables) for vs_cable_length.png; and
    (cable, period_mm) of periodic cable-length findings.
    """
    pos_notes, len_notes, periods = {}, {}, []
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


def section_variables(diag, page, P):
    page.add("<h2>5. Residual versus physical variables</h2>")
    us = _dict(diag, "unexplained_structure")
    findings = []
    if us is None:
        page.note("\"unexplained_structure\" is not in the diagnosis.")
    else:
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
            page.add("<p>No trend or periodicity found in the residual.</p>")
    pos_notes, len_notes, periods = _route_findings(findings)
    if not P.ok:
        page.add("<p>Plots not available: no per-position data.</p>")
        return
    pal = plt.get_cmap("tab10")

    # Length residual per cable vs that cable's length.
    if P.lengths is not None and P.length_residual is not None:
        def draw():
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
    else:
        page.note("\"positions.lengths_mm\" or \"positions.length_residual_mm\" is missing: "
                  "no length-residual plot.")

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
    def draw():
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


def section_comparison(runs, page):
    """runs: [(path, diag)], earliest first, the report's run last."""
    page.add("<h2>6. Error fell? Runs compared</h2>")
    labels = [_label(d) for _, d in runs]
    rows = []
    rms = np.full((len(runs), 3), np.nan)
    for i, (path, d) in enumerate(runs):
        e = _dict(d, "error_mm")
        if e is None:
            page.note(f"{os.path.basename(path)}: no \"error_mm\"; its bars are missing.")
        for k, a in enumerate(AXES):
            rms[i, k] = _num((_dict(e, a) or {}).get("rms"))
        ex = d.get("explained")
        rows.append([_e(labels[i]), _e(os.path.basename(path)),
                     *[fmt_mm(rms[i, k]) if np.isfinite(rms[i, k]) else "n/a" for k in range(3)],
                     fmt_g(d.get("chi2_per_dof"), 4),
                     "yes" if ex is True else "no" if ex is False else "n/a"])
    page.add(_table(["model", "file", "x RMS (mm)", "y RMS (mm)", "z RMS (mm)", "chi²/dof",
                     "explained"], rows, "stats"))
    def draw():
        fig, ax = plt.subplots(figsize=(max(7.0, 1.2 * len(runs) + 5), 4.4))
        w = 0.8 / len(runs)
        cmap = plt.get_cmap("viridis")
        for i in range(len(runs)):
            xs = np.arange(3) + (i - (len(runs) - 1) / 2) * w
            lab = labels[i] if len(labels[i]) <= 40 else labels[i][:37] + "..."
            bars = ax.bar(xs, np.nan_to_num(rms[i]), w, label=lab,
                          color=cmap(i / max(1, len(runs) - 1)))
            for b, v in zip(bars, rms[i]):
                ax.text(b.get_x() + b.get_width() / 2, b.get_height(),
                        fmt_g(v, 3) if np.isfinite(v) else "n/a",
                        ha="center", va="bottom", fontsize=7)
        nf = _dict(runs[-1][1], "noise_floor_mm")
        if nf is not None:
            for k, a in enumerate(AXES):
                v = _num((_dict(nf, a) or {}).get("rms"))
                if np.isfinite(v):
                    ax.hlines(v, k - 0.45, k + 0.45, colors="k", linestyles="--", lw=1,
                              label="noise floor" if k == 0 else None)
        ax.set_xticks(range(3), [f"{a} error" for a in AXES])
        ax.set_ylabel("RMS position error (mm)")
        ax.set_title("Position error RMS per run")
        ax.legend(fontsize=8)
        ax.grid(axis="y", alpha=0.3)
        _fit(fig, np.array([[ax]]))
        return fig
    page.figure("comparison.png", draw, "error per run", "RMS position error per axis for each run, "
                "labelled by the effects in its model, earliest first; the dashed line is "
                "the noise floor of the report's run. Adding the right effect makes the "
                "bars fall to the floor; an effect that only fits noise barely moves them "
                "(check the validation table).")


CSS = """
body{font-family:system-ui,sans-serif;max-width:1200px;margin:1em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.6em 0;font-size:.88em}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:right}
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}
table.facts td{text-align:left}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.88em;color:#444;max-width:60em}
.verdict{font-size:1.05em;background:#f7f7f2;padding:.5em .8em;border-left:4px solid #888}
.ok{color:#176117;font-weight:bold}.bad{color:#a11;font-weight:bold}.na{color:#777}
.notes{background:#fff7e0;border:1px solid #e0c060;padding:.4em 1em;font-size:.9em}
"""


# ----------------------------------------------------------------------- driver

def _render(runs, tmp):
    """Draw everything for runs[-1] (+ comparison) into tmp; return (html, figs)."""
    path, diag = runs[-1]
    page = Page()
    P = Positions(diag, page)
    sections = [lambda: section_summary(diag, page),
                lambda: section_maps(diag, page, P),
                lambda: section_candidates(diag, page),
                lambda: section_search(diag, page),
                lambda: section_fingerprints(diag, page, P),
                lambda: section_variables(diag, page, P)]
    if len(runs) > 1:
        sections.append(lambda: section_comparison(runs, page))
    for s in sections:
        try:
            s()
        except Exception as e:  # a broken section must not lose the rest of the report
            plt.close("all")
            msg = f"A section could not be drawn ({type(e).__name__}: {e})."
            page.note(msg)
            page.add(f"<p class=\"bad\">{_e(msg)}</p>")
            print(f"cdm.report: warning: {path}: {msg}", file=sys.stderr)
    _draw_all(page.figures, tmp)
    figs = []
    for i, part in enumerate(page.parts):
        if not isinstance(part, _Figure):
            continue
        if part.error is None:
            figs.append(part.name)
            page.parts[i] = _img(part.name, part.alt, part.caption)
        else:
            msg = f"The figure {part.name} could not be drawn ({part.error})."
            page.note(msg)
            page.parts[i] = f"<p class=\"bad\">{_e(msg)}</p>"
            print(f"cdm.report: warning: {path}: {msg}", file=sys.stderr)
    title = f"cdm calibration diagnosis: {_label(diag)}"
    notes = ""
    if page.notes:
        notes = ('<div class="notes"><b>Notes</b> (parts of the diagnosis that were missing '
                 'or unusable):<ul>' + "".join(f"<li>{_e(n)}</li>" for n in page.notes)
                 + "</ul></div>")
    files = _e(os.path.basename(path))
    if len(runs) > 1:
        files += ", compared with the earlier " + ", ".join(
            _e(os.path.basename(p)) for p, _ in runs[:-1])
    doc = (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
           f"<title>{_e(title)}</title><style>{CSS}</style></head><body>"
           f"<h1>{_e(title)}</h1><p>From {files}.</p>{notes}"
           + '<nav class="toc"><b>Contents</b><ol>'
           + "".join(f'<li><a href="#s{i + 1}">{t}</a></li>' for i, t in enumerate(page.toc))
           + "</ol></nav>"
           + "\n".join(page.parts) + "</body></html>\n")
    return doc, figs


def _run(item, i):
    if isinstance(item, dict):
        return f"run {i + 1}", _plain(item)
    return str(item), load_diagnosis(item)


def _plain(obj):
    """numpy arrays / scalars (as cdm.diagnose returns them) -> lists / floats."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def write_report(runs, out):
    """Write the report on runs[-1], comparing it with the earlier runs[:-1].

    Each run is a diagnosis JSON path or a loaded diagnosis dict. Raises
    DiagnosisError (naming the file) before writing anything if one is unusable.
    Returns the paths written (figures, then index.html).
    """
    if isinstance(runs, (str, os.PathLike, dict)):
        runs = [runs]
    runs = [_run(r, i) for i, r in enumerate(runs)]
    if not runs:
        raise DiagnosisError("no diagnosis given")
    os.makedirs(out, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix="tmp-report-", dir=out)
    try:
        doc, figs = _render(runs, tmp)
        with open(os.path.join(tmp, "index.html"), "w", encoding="utf-8") as f:
            f.write(doc)
        # Move into place: figures first, the page last; remove stale figures.
        keep = set(figs)
        for name in os.listdir(out):
            if (name.endswith(".png") and name.startswith(FIGURE_PREFIXES)
                    and name not in keep and os.path.isfile(os.path.join(out, name))):
                os.remove(os.path.join(out, name))
        for name in figs + ["index.html"]:
            os.replace(os.path.join(tmp, name), os.path.join(out, name))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        plt.close("all")
    return [os.path.join(out, n) for n in figs + ["index.html"]]


def main(argv=None):
    ap = argparse.ArgumentParser(
        prog="python3 -m cdm.report",
        description="Figures and index.html for `cdm calib diagnose --json` output. Files are "
                    "in chronological order: the last one is the diagnosis reported on, the "
                    "earlier ones (and --before files) are compared with it.")
    ap.add_argument("diagnosis", nargs="+", metavar="DIAG.json",
                    help="diagnosis JSON files, earliest first; the last is reported on")
    ap.add_argument("--before", action="append", default=[], metavar="EARLIER.json",
                    help="an earlier run to compare with (repeatable; comes before the "
                         "positional files)")
    ap.add_argument("--out", required=True, metavar="DIR", help="report directory")
    args = ap.parse_args(argv)
    runs = args.before + args.diagnosis
    try:
        written = write_report(runs, args.out)
    except DiagnosisError as e:
        print(f"cdm.report: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"cdm.report: error: cannot write the report to {args.out}: {e}", file=sys.stderr)
        return 1
    print(f"cdm.report: report on {runs[-1]}"
          + (f", compared with {', '.join(runs[:-1])}" if len(runs) > 1 else "")
          + f": wrote {len(written) - 1} figures and {os.path.join(args.out, 'index.html')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
