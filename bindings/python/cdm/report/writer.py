"""The report's driver: the sections in page order, the figures drawn, the files
moved into place; and the command line."""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Set, Tuple, Union

from .loading import Diag

import argparse
import json
import os
import shutil
import sys
import tempfile

import matplotlib.pyplot as plt

from . import sections
from .check import is_check, render_check
from .drawing import _draw_all
from .loading import DiagnosisError, Positions, _label, _run
from .page import Page, _e, document, place_figures

# The report's claim on its directory: the names of the files it wrote there,
# one a line. A directory is the report's when it created it, when it was
# empty, or when it holds this file; a report removes only files this list
# names (an earlier report's figures it does not draw again), never a file
# it did not write, whatever its name.
MARKER = ".cdm-report"


class ReportDirError(Exception):
    """The output directory is not the report's to write into."""


def _claim(out: "Union[str, os.PathLike[str]]", inputs: Sequence[Any] = ()) -> Set[str]:
    """Makes `out` the report's directory or refuses it; returns the names an
    earlier report wrote there (empty for a new or empty directory). The
    report's own inputs inside `out` (the diagnosis `cdm calib diagnose
    --report` writes there) do not make it someone else's."""
    if not os.path.lexists(out):
        os.makedirs(out)
        return set()
    if not os.path.isdir(out):
        raise NotADirectoryError(f"{out} exists and is not a directory")
    marker = os.path.join(out, MARKER)
    if os.path.isfile(marker) and not os.path.islink(marker):
        with open(marker, encoding="utf-8") as f:
            # Plain names only: a marker edited to name ../x or a path removes nothing outside.
            return {n for n in f.read().splitlines() if n and n == os.path.basename(n) and n not in (".", "..")}
    own = {os.path.realpath(p) for p in inputs}
    if [n for n in os.listdir(out) if os.path.realpath(os.path.join(out, n)) not in own]:
        raise ReportDirError(f"{out} is not empty and holds no report ({MARKER} is missing): the report writes "
                             "only into a new or empty directory, or one an earlier report wrote; give another "
                             "--out/--report directory")
    return set()


def _write_marker(out: "Union[str, os.PathLike[str]]", tmp: str, names: Set[str]) -> None:
    path = os.path.join(tmp, MARKER)
    with open(path, "w", encoding="utf-8") as f:
        f.write("".join(n + "\n" for n in sorted(names)))
        f.flush()
        os.fsync(f.fileno())
    os.replace(path, os.path.join(out, MARKER))


def _render(runs: List[Tuple[str, Diag]], tmp: str) -> Tuple[str, List[str]]:
    """Draw everything for runs[-1] (+ comparison) into tmp; return (html, figs)."""
    path, diag = runs[-1]
    page = Page()
    P = Positions(diag, page)
    for s in sections.in_order(runs, page, P):
        try:
            s()
        except Exception as e:  # a broken section must not lose the rest of the report
            plt.close("all")
            msg = f"A section could not be drawn ({type(e).__name__}: {e})."
            page.note(msg)
            page.add(f"<p class=\"bad\">{_e(msg)}</p>")
            print(f"cdm.report: warning: {path}: {msg}", file=sys.stderr)
    _draw_all(page.figures, tmp)
    figs = place_figures(page, path)
    title = f"cdm calibration diagnosis: {_label(diag)}"
    files = _e(os.path.basename(path))
    if len(runs) > 1:
        files += ", compared with the earlier " + ", ".join(
            _e(os.path.basename(p)) for p, _ in runs[:-1])
    return document(title, files, page.notes, page.toc, [p for p in page.parts if isinstance(p, str)]), figs


Run = Union[str, "os.PathLike[str]", Diag]


def _as_check(items: Sequence[Run]) -> Optional[Tuple[str, Dict[str, Any]]]:
    """(name, result) when the one input is a `cdm calib check` result; None
    otherwise (a diagnosis, or a file _run will name as unreadable)."""
    if len(items) != 1:
        return None
    item = items[0]
    if isinstance(item, dict):
        return ("check", item) if is_check(item) else None
    try:
        with open(item, encoding="utf-8") as f:
            d = json.load(f)
    except (OSError, ValueError):
        return None
    return (os.fspath(item), d) if is_check(d) else None


def write_report(runs: Union[Run, Sequence[Run]], out: Union[str, "os.PathLike[str]"],
                 claim: bool = False) -> List[str]:
    """Write the report on runs[-1], comparing it with the earlier runs[:-1].

    Each run is a diagnosis JSON path or a loaded diagnosis dict; a single
    `cdm calib check` result (its "tool") gets the check's page instead. Raises
    DiagnosisError (naming the file) before writing anything if one is unusable.
    Returns the paths written (figures, then index.html). `claim`: the last
    run is a JSON the caller wrote into `out` for this report, listed as
    the report's own (`cdm calib ... --report DIR` without --json).
    """
    items: Sequence[Run] = [runs] if isinstance(runs, (str, os.PathLike, dict)) else runs
    inputs = [r for r in items if isinstance(r, (str, os.PathLike))]
    check = _as_check(items)
    if check is not None:  # a calibration checked on another session: its own page
        def render(tmp: str) -> Tuple[str, List[str]]:
            return render_check(check[0], check[1], tmp)
    else:
        loaded = [_run(r, i) for i, r in enumerate(items)]
        if not loaded:
            raise DiagnosisError("no diagnosis given")

        def render(tmp: str) -> Tuple[str, List[str]]:
            return _render(loaded, tmp)
    earlier = _claim(out, inputs)
    tmp = tempfile.mkdtemp(prefix="tmp-report-", dir=out)
    try:
        doc, figs = render(tmp)
        with open(os.path.join(tmp, "index.html"), "w", encoding="utf-8") as f:
            f.write(doc)
        # With `claim` (`cdm calib diagnose/check --report` wrote the JSON
        # reported on into `out` itself), that JSON is the report's file
        # too: listed, kept. A file the user named (--json) is never claimed.
        last = items[-1]
        own_inputs = {os.path.basename(last)} if claim and isinstance(last, (str, os.PathLike)) and os.path.realpath(
            os.path.dirname(os.path.abspath(last))) == os.path.realpath(out) else set()
        new = set(figs + ["index.html"]) | own_inputs
        # The claim first covers both reports' files (a stop half-way leaves
        # none unclaimed), then the new one's alone.
        _write_marker(out, tmp, earlier | new)
        # Move into place: figures first, the page last; then remove the
        # earlier report's figures this one does not have.
        for name in figs + ["index.html"]:
            os.replace(os.path.join(tmp, name), os.path.join(out, name))
        # Never a file this report read (an earlier diagnosis compared with).
        read_here = {os.path.basename(p) for p in inputs
                     if os.path.realpath(os.path.dirname(os.path.abspath(p))) == os.path.realpath(out)}
        for name in sorted(earlier - new - read_here):
            path = os.path.join(out, name)
            if os.path.isfile(path) and not os.path.islink(path):
                os.remove(path)
        _write_marker(out, tmp, new)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        plt.close("all")
    return [os.path.join(out, n) for n in figs + ["index.html"]]


def main(argv: Optional[List[str]] = None) -> int:
    """The command line: ``python3 -m cdm.report [EARLIER.json ...] DIAG.json --out DIR``; the exit code."""
    ap = argparse.ArgumentParser(
        prog="python3 -m cdm.report",
        description="Figures and index.html for `cdm calib diagnose --json` output. Files are "
                    "in chronological order: the last one is the diagnosis reported on, the "
                    "earlier ones (and --before files) are compared with it. A single "
                    "`cdm calib check --json` output gets the check's page.")
    ap.add_argument("diagnosis", nargs="+", metavar="DIAG.json",
                    help="diagnosis JSON files, earliest first; the last is reported on")
    ap.add_argument("--before", action="append", default=[], metavar="EARLIER.json",
                    help="an earlier run to compare with (repeatable; comes before the "
                         "positional files)")
    ap.add_argument("--out", required=True, metavar="DIR", help="report directory")
    ap.add_argument("--claim", action="store_true",
                    help="the last DIAG.json was written into DIR for this report (by `cdm calib ... --report`): "
                         "list it as the report's own")
    args = ap.parse_args(argv)
    runs = args.before + args.diagnosis
    try:
        written = write_report(runs, args.out, claim=args.claim)
    except (DiagnosisError, ReportDirError) as e:
        print(f"cdm.report: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"cdm.report: error: cannot write the report to {args.out}: {e}", file=sys.stderr)
        return 1
    print(f"cdm.report: report on {runs[-1]}"
          + (f", compared with {', '.join(runs[:-1])}" if len(runs) > 1 else "")
          + f": wrote {len(written) - 1} figures and {os.path.join(args.out, 'index.html')}")
    return 0
