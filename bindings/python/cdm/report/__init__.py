"""Figures and an HTML page for a ``cdm calib diagnose`` result.

The numbers come from the C library (``cdm calib diagnose ... --json DIAG.json``);
this package only draws them::

    python3 -m cdm.report [EARLIER.json ...] DIAG.json --out DIR
    python3 -m cdm.report DIAG.json --before EARLIER.json [--before ...] --out DIR
    python3 bindings/python/cdm/report.py ...        (same, from a source tree)

Files are in chronological order: the LAST positional file is the diagnosis the
report is about; the others, and any --before files (which come first), are
earlier runs (e.g. the nominal diagnosis before an effect was added), shown in
an "error fell" comparison in that order. This is the order `cdm calib diagnose
--before B.json ... --report DIR` passes them in.

From Python: ``write_report([earlier, ..., current], "DIR")`` where each run is
a path or an already loaded diagnosis dict (lists or numpy arrays).

A single ``cdm calib check --json`` result (its "tool" says so) gets a page of
its own instead (module check): the measured error at each position against
the error the calibration's accuracy map predicted there.

DIR receives PNG figures and ``index.html`` (relative image paths, inline CSS,
no JavaScript, no external resources). Everything is written to a temporary
directory inside DIR first and moved into place only when complete.

The figures are drawn in forked worker processes, one per processor this
process may use (CDM_REPORT_JOBS=N sets how many; 1 draws in this process, as
happens anyway where fork is missing or the caller runs other threads). A figure
that cannot be drawn becomes a note in its place.

Exit codes: 0 report written; 2 an input file is missing, does not parse or is
not a diagnosis (the message names the file); 1 the report could not be written.

Only numpy, matplotlib and the standard library are imported, and nothing of
the rest of the cdm package (the ctypes binding).

The modules: loading (reading and checking the JSON), page (the HTML),
figures (drawing helpers), drawing (the worker processes), sections (one
module per part of the page), check (a check's page), writer (the driver and
the command line).
"""
from __future__ import annotations


from .loading import DiagnosisError, load_diagnosis
from .writer import main, write_report

__all__ = ["DiagnosisError", "load_diagnosis", "write_report", "main"]
