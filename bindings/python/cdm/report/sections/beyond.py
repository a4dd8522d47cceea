"""Section 5b: beyond the catalogue. The stand-ins the diagnosis named (fitted
values an effect's own physics does not allow), the term it proposes for
what the catalogue lacks, and the jig's errors it doubts: the library's
words and numbers (docs/calibration.md, "Stand-ins, the term the catalogue
lacks, and the jig's errors in doubt"), none recomputed here."""
from __future__ import annotations

from typing import Any, TYPE_CHECKING

if TYPE_CHECKING:
    from ..page import Page

from ..loading import Diag

from ..loading import _dict, _list, _num
from ..page import _e, _table, fmt_g


def _stand_in_rows(items: Any, whose: str) -> Any:
    rows = []
    for s in items or []:
        if isinstance(s, dict):
            rows.append([_e(whose), _e(str(s.get("effect", "?"))), _e(str(s.get("kind", "?"))),
                         _e(str(s.get("text", "")))])
    return rows


def section_beyond(diag: Diag, page: Page) -> None:
    rec = _dict(diag, "recommended") or {}
    rows = _stand_in_rows(_list(rec, "stand_ins"), "recommended") + _stand_in_rows(_list(diag, "stand_ins"), "yours")
    disc = _dict(diag, "discovered")
    att = _dict(_dict(diag, "jig") or {}, "attribution") or {}
    if not rows and disc is None and not att.get("text"):
        return
    page.add("<h2>5b. Beyond the catalogue</h2>")
    if rows:
        page.add("<p>Stand-ins: effects whose fitted values their own physics does not allow. The data reach "
                 "the noise floor with them, but they are not the explanation.</p>")
        page.add(_table(["model", "effect", "kind", "what"], rows, "stats"))
    else:
        page.add("<p>No stand-in: every fitted value is within its effect's plausible range.</p>")
    if disc is not None:
        terms = []
        for t in _list(disc, "terms") or []:
            if isinstance(t, dict):
                terms.append([_e(str(t.get("term", "?"))), _e(str(t.get("variable", "?"))),
                              f"{fmt_g(t.get('coefficient'), 4)} ± {fmt_g(t.get('std'), 2)}",
                              fmt_g(t.get("delta_chi2"), 5), fmt_g(t.get("p_value"), 2), _e(str(t.get("shape", "")))])
        xr = _num(disc.get("x_rms_fixture_out_mm"))
        bic = _num(disc.get("bic_change_vs_compared"))
        against = disc.get("compared_with") if isinstance(disc.get("compared_with"), str) else "the model compared"
        page.add("<p>A term the catalogue lacks, proposed by a sparse regression of the reading residual over "
                 "physical variables (a hypothesis for the physics to confirm, never the recommended model): "
                 f"x RMS {fmt_g(xr, 4)} mm with it (the fixture's per-height offsets out)"
                 + (f", BIC {fmt_g(bic, 6)} against {_e(against)}" if bic == bic else "") + ".</p>")
        page.add(_table(["term", "variable", "coefficient (mm, L in m)", "Δχ²", "p", "shape"], terms, "stats"))
    if att.get("text"):
        page.add(f"<p>The jig's errors in doubt: {_e(str(att['text']))}.</p>")
