"""Section 3: the candidate effects ranked, and section 3b: where the model search led."""
from __future__ import annotations

from typing import Any, Dict, List, Optional, TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from ..page import Page

from ..loading import Diag

import numpy as np
import matplotlib.pyplot as plt

from ..figures import _agg, _first_label_reach, _fit
from ..loading import AXES, _dict, _finite, _list, _num
from ..page import _e, _table, fmt_g, fmt_mm


def _fmt_list(v: Any) -> str:
    return ", ".join(str(x) for x in v) if isinstance(v, list) and v else ""


def section_candidates(diag: Diag, page: Page) -> None:
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
            _ranking_figure(diag, page, cands, *metric)
        page.add(_candidates_table(cands))
    ins = _list(diag, "inseparable")
    if ins:
        page.add("<h3>Inseparable effects</h3><ul>")
        for s in ins:
            if isinstance(s, dict):
                page.add(f"<li><b>{_e(_fmt_list(s.get('effects')))}</b>: "
                         f"{_e(s.get('separate_by', 'no separating measurement given'))}</li>")
        page.add("</ul>")


def _candidates_table(cands: List[Any]) -> Any:
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
    return _table(["effect", "score", "Δχ²", "BIC change", "params",
                   "x RMS after (mm)", "y RMS after (mm)", "z RMS after (mm)",
                   "corr. with residual", "explained after", "confused with"],
                  rows, "cands")


def _confusion_colours(cands: List[Any]) -> Any:
    """One colour per set of effects the data cannot tell apart; grey for the others."""
    groups: Dict[Any, Any] = {}
    colours: List[Any] = []
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
    return colours


def _ranking_figure(diag: Diag, page: Page, cands: List[Any], key: str, label: Optional[str]) -> None:
    names = [str(c.get("effect", "?")) for c in cands]
    vals = np.array([_num(c.get(key)) for c in cands])
    colours = _confusion_colours(cands)
    # Right panel: the x RMS each candidate leaves, on a log scale
    # against the current model's and the noise floor. With a large
    # residual every candidate removes most of the chi-square and the
    # BIC bars look alike; what is left is what tells them apart.
    after_x = np.array([_num((_dict(_dict(c, "error_mm_after") or {}, "x") or {}).get("rms"))
                        for c in cands])
    show_after = np.isfinite(after_x).any() and np.nanmin(after_x) > 0

    def draw() -> Any:
        fig, axs = plt.subplots(1, 2 if show_after else 1, figsize=(13 if show_after else 8.5,
                                0.45 * len(cands) + 1.6), squeeze=False)
        ax = axs[0][0]
        yy = np.arange(len(cands))
        if show_after:
            _after_panel(diag, axs[0][1], yy, after_x, colours)
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


def _after_panel(diag: Diag, ax2: Axes, yy: Any, after_x: Any, colours: Any) -> None:
    ax2.barh(yy, np.where(np.isfinite(after_x), after_x, np.nan), color=colours)
    ax2.set_xscale("log")
    ax2.set_yticks(yy, [""] * len(yy))
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


def section_search(diag: Diag, page: Page) -> None:
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

            def draw() -> Any:
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
