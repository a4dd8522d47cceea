"""Section 6: the runs compared (did the error fall?)."""
from __future__ import annotations

from typing import Any, List, TYPE_CHECKING, Tuple

if TYPE_CHECKING:
    from ..page import Page

from ..loading import Diag

import os

import numpy as np
import matplotlib.pyplot as plt

from ..figures import _fit
from ..loading import AXES, _dict, _label, _num
from ..page import _e, _table, fmt_g, fmt_mm


def section_comparison(runs: List[Tuple[str, Diag]], page: Page) -> None:
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

    def draw() -> Any:
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
                              # None: no legend entry (matplotlib's stubs say str)
                              label="noise floor" if k == 0 else None)  # type: ignore[arg-type]
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
