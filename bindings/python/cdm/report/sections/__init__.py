"""The page's sections, each a function that adds its HTML and describes its
figures to the Page (drawn later, see drawing.py)."""
from __future__ import annotations

from typing import Any, List, TYPE_CHECKING, Tuple

if TYPE_CHECKING:
    from ..page import Page
    from ..loading import Positions

from ..loading import Diag

from .accuracy import section_accuracy
from .beyond import section_beyond
from .candidates import section_candidates, section_search
from .comparison import section_comparison
from .fingerprints import section_fingerprints
from .maps import section_cut, section_maps
from .summary import section_summary
from .variables import section_variables

__all__ = ["section_summary", "section_maps", "section_cut", "section_accuracy", "section_candidates",
           "section_search", "section_fingerprints", "section_variables", "section_beyond", "section_comparison",
           "in_order"]


def in_order(runs: List[Tuple[str, Diag]], page: Page, P: Positions) -> Any:
    """The sections of the report on runs[-1], in page order, as calls without arguments."""
    diag = runs[-1][1]
    sections = [lambda: section_summary(diag, page),
                lambda: section_maps(diag, page, P),
                lambda: section_accuracy(diag, page),
                lambda: section_candidates(diag, page),
                lambda: section_search(diag, page),
                lambda: section_fingerprints(diag, page, P),
                lambda: section_variables(diag, page, P),
                lambda: section_beyond(diag, page)]
    if len(runs) > 1:
        sections.append(lambda: section_comparison(runs, page))
    return sections
