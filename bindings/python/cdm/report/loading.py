"""Reading diagnosis files: the checks that name what is unusable, and the
tolerant accessors every section reads the diagnosis through (a missing or
malformed value becomes None or nan, never an exception)."""
from __future__ import annotations

from typing import Any, Dict, List, Optional, TYPE_CHECKING, Tuple, Union

if TYPE_CHECKING:
    from typing import TypeGuard  # Python 3.10; only read by type checkers here
    from .page import Page

import math
import json
import os

import numpy as np

AXES = ("x", "y", "z")

#: A diagnosis as its JSON reads (docs/calibration.md gives the schema).
Diag = Dict[str, Any]


class DiagnosisError(Exception):
    """An input file that cannot be used; the message names the file."""


def load_diagnosis(path: str) -> Diag:
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


def _num(v: Any) -> float:
    """A float, or nan for None / non-numbers / booleans."""
    if isinstance(v, bool) or v is None:
        return math.nan
    if isinstance(v, (int, float)):
        return float(v)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _finite(v: Any) -> TypeGuard[float]:
    """v is a finite number (not a bool)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _dict(d: Any, key: str) -> Optional[Dict[str, Any]]:
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, dict) else None


def _list(d: Any, key: str) -> Optional[List[Any]]:
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, list) else None


def _array(v: Any, width: Optional[int] = None) -> Any:
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


def _label(diag: Diag) -> str:
    model = diag.get("model")
    if isinstance(model, list):
        return "nominal" if not model else " + ".join(str(m) for m in model)
    return "(model not given)"


class Positions:
    """The per-position arrays, checked for a common length P."""

    def __init__(self, diag: Diag, page: Page) -> None:
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

        def get(key: str, width: Optional[int] = None, required: bool = False) -> Any:
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


def _run(item: Union[str, "os.PathLike[str]", Diag], i: int) -> Tuple[str, Diag]:
    if isinstance(item, dict):
        return f"run {i + 1}", _plain(item)
    return str(item), load_diagnosis(os.fspath(item))


def _plain(obj: Any) -> Any:
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
