"""The HTML page: number formatting, escaping, tables, and the Page that the
sections fill in order (HTML parts and the places of figures still to draw)."""
from __future__ import annotations

from typing import Any, Callable, Iterable, List, Optional, Sequence, TYPE_CHECKING, Union

if TYPE_CHECKING:
    from matplotlib.figure import Figure

import html
import sys

from .loading import _finite


def fmt_mm(v: Any) -> str:
    """Millimetre statistics: 4 decimals as the seed's Table 1; 'n/a' if missing."""
    return f"{v:.4f}" if _finite(v) else "n/a"


def fmt_g(v: Any, digits: int = 6) -> str:
    return f"{v:.{digits}g}" if _finite(v) else "n/a"


def _e(s: Any) -> str:
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

    def __init__(self, name: str, draw: Callable[[], Figure], alt: str, caption: str, weight: float = 1,
                 group: Optional[str] = None, build: float = 0) -> None:
        self.name, self.draw, self.alt, self.caption = name, draw, alt, caption
        self.weight, self.group, self.build = weight, group, build
        self.error = None  # why it could not be drawn, or None


class Page:
    """Collects HTML sections and notes about what was missing."""

    def __init__(self) -> None:
        self.parts: List[Union[str, _Figure]] = []  # HTML strings and _Figure places, in page order
        self.notes: List[str] = []
        self.toc: List[str] = []  # section titles (already escaped HTML), in order
        self.figures: List[_Figure] = []

    def note(self, text: str) -> None:
        self.notes.append(text)

    def figure(self, name: str, draw: Callable[[], Figure], alt: str, caption: str, weight: float = 1,
               group: Optional[str] = None, build: float = 0) -> None:
        """Keeps the place of a figure that draw() will make."""
        f = _Figure(name, draw, alt, caption, weight, group, build)
        self.figures.append(f)
        self.parts.append(f)

    def add(self, s: Any) -> None:
        # Section headings get an anchor for the table of contents.
        if s.startswith("<h2>") and s.endswith("</h2>"):
            self.toc.append(s[4:-5])
            s = f'<h2 id="s{len(self.toc)}">{s[4:-5]}</h2>'
        self.parts.append(s)


def _table(header: Sequence[str], rows: Iterable[Sequence[Any]], cls: str = "") -> str:
    h = "".join(f"<th>{_e(c)}</th>" for c in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table class="{cls}"><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>'


def _img(name: str, alt: str, caption: str) -> str:
    return (f'<figure><img src="{_e(name)}" alt="{_e(alt)}">'
            f"<figcaption>{caption}</figcaption></figure>")


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


def document(title: str, files: str, notes: List[str], toc: List[str], parts: List[str]) -> str:
    """The whole page: title, source files (escaped HTML), notes, contents, parts."""
    notes_html = ""
    if notes:
        notes_html = ('<div class="notes"><b>Notes</b> (parts of the diagnosis that were missing '
                      'or unusable):<ul>' + "".join(f"<li>{_e(n)}</li>" for n in notes)
                      + "</ul></div>")
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{_e(title)}</title><style>{CSS}</style></head><body>"
            f"<h1>{_e(title)}</h1><p>From {files}.</p>{notes_html}"
            + '<nav class="toc"><b>Contents</b><ol>'
            + "".join(f'<li><a href="#s{i + 1}">{t}</a></li>' for i, t in enumerate(toc))
            + "</ol></nav>"
            + "\n".join(parts) + "</body></html>\n")


def place_figures(page: Page, label: str) -> List[str]:
    """After the figures are drawn: each figure's place becomes its image, or
    a note saying why it could not be drawn (also on stderr, naming
    `label`, the input reported on). Returns the names of those drawn."""
    figs: List[str] = []
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
            print(f"cdm.report: warning: {label}: {msg}", file=sys.stderr)
    return figs
