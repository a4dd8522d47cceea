"""Section 4: the fingerprints of the top candidates beside the current residual."""
from __future__ import annotations

from typing import Any, TYPE_CHECKING

if TYPE_CHECKING:
    from ..page import Page
    from ..loading import Positions

from ..loading import Diag

import math
import re

import numpy as np

from ..figures import (_colorbar, _drop_frames, _keep, _kept, _map, _map_grid, _outer_labels,
                       _raster, _regular_grid, _symnorm)
from ..loading import _array, _dict, _finite, _list
from ..page import _e, fmt_g


def _corr(a: Any, b: Any) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return math.nan
    a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
    d = math.sqrt(float((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / d) if d > 0 else math.nan


def section_fingerprints(diag: Diag, page: Page, P: Positions) -> None:
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

        def draw(fp: Any = fp, title: str = title) -> Any:
            nf = _symnorm(fp[:, 0])
            grids = [_regular_grid(P.ref[P.height_index[hi], 1], P.ref[P.height_index[hi], 2])
                     for hi in hsel]
            # Every candidate's figure has the same layout and bottom row: a process
            # redraws its last one with this one's top row (values, colour scale) and title.
            sig = (None if any(g is None for g in grids) else
                   (nf.clipped,) + tuple(g[0].tobytes() + g[1].tobytes() for g in grids))
            last = _kept("fingerprint")
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
                _keep("fingerprint", sig, fig, top)
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
