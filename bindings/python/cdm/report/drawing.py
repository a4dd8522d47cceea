"""Drawing the page's figures: in this process, or in forked worker processes
that each draw a share of them (CDM_REPORT_JOBS sets how many)."""
from __future__ import annotations

from typing import Any, Dict, List, Optional, TYPE_CHECKING, Tuple

if TYPE_CHECKING:
    from .page import _Figure

import concurrent.futures
import math
import multiprocessing
import os
import sys
import threading

import numpy as np
import matplotlib
import matplotlib.pyplot as plt

from .figures import _RC, _drop_frames, _forget_frames, _is_kept, _save_png
from .loading import DiagnosisError


def _draw_one(f: Any, tmp: str) -> Any:
    """Draw one figure into tmp; None, or why it could not be drawn."""
    try:
        with matplotlib.rc_context(_RC):  # type: ignore[arg-type]  # keys checked by matplotlib
            fig = f.draw()
            try:
                _save_png(fig, os.path.join(tmp, f.name))
            finally:
                if not _is_kept(fig):
                    plt.close(fig)
    except Exception as e:  # one broken figure must not lose the rest of the report
        _forget_frames()  # a figure left half redrawn
        plt.close("all")
        return f"{type(e).__name__}: {e}"
    return None


# The figures a pool's worker processes draw: set before the pool forks them, so
# that the workers inherit the drawing closures instead of receiving them pickled.
_PENDING: Optional[Tuple[List[_Figure], str]] = None


def _draw_pending(task: Any) -> Any:
    assert _PENDING is not None  # set before the pool forks
    figures, tmp = _PENDING
    try:
        return [_draw_one(figures[i], tmp) for i in task]
    finally:
        _drop_frames()


def _tasks(figures: List[_Figure], n: int) -> Any:
    """The figures' indices in tasks for n processes, heaviest task first.

    A group's figures go into as few tasks (consecutive runs) as keep every
    task under an n-th of the total, since each task builds the group's figure
    once more; every other figure is a task of its own.
    """
    total = (sum(f.weight for f in figures)
             + sum({f.group: f.build for f in figures if f.group is not None}.values()))
    groups: Dict[str, List[int]] = {}
    tasks: List[Tuple[List[int], float]] = []
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


def _workers(n: int) -> int:
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


def _draw_all(figures: List[_Figure], tmp: str) -> None:
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
