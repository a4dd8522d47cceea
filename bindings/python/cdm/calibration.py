"""Calibrations: load, corrected forward kinematics and its inverse."""
from __future__ import annotations

import ctypes
import math
import os
from typing import Any, Iterable, List, Tuple, Union

from . import _native
from .constants import Error
from .errors import CdmError


def _vector(values: Iterable[float], n: int, what: str) -> Any:
    try:
        vals = [float(v) for v in values]
    except (TypeError, ValueError):
        raise ValueError("%s must be %d numbers, got %r" % (what, n, values)) from None
    if len(vals) != n:
        raise ValueError("%s must be %d numbers, got %d" % (what, n, len(vals)))
    bad = [i for i, v in enumerate(vals) if not math.isfinite(v)]
    if bad:
        raise ValueError("%s[%d] is %r: must be finite" % (what, bad[0], vals[bad[0]]))
    return (ctypes.c_double * n)(*vals)


class Calibration(_native.Closing):
    """A fitted calibration (cdm_calibration). Create with Calibration.load(path)
    or Calibration.parse(text); free with close() or a with-block (or let the
    garbage collector do it). Read-only: safe to share between threads."""

    def __init__(self, handle: ctypes.c_void_p, source: str) -> None:
        self._h: ctypes.c_void_p | None = handle
        self.source = source

    @classmethod
    def load(cls, path: Union[str, os.PathLike[str]]) -> Calibration:
        """Loads a calibration JSON file; errors name the file, line and column."""
        path = os.fspath(path)
        h = ctypes.c_void_p()
        rc = _native.lib().cdm_calibration_load(_native.c_path(path, "calibration path"), ctypes.byref(h))
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_load")
        return cls(h, path)

    @classmethod
    def parse(cls, text: Union[str, bytes]) -> Calibration:
        """The same from JSON text (str or bytes)."""
        data = text.encode("utf-8") if isinstance(text, str) else bytes(text)
        h = ctypes.c_void_p()
        rc = _native.lib().cdm_calibration_parse(data, len(data), ctypes.byref(h))
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_parse")
        return cls(h, "<text>")

    def _handle(self, function: str) -> ctypes.c_void_p:
        if self._h is None:
            raise CdmError(Error.CDM_ERR_INVALID_ARG, "calibration %s is closed" % self.source, function=function)
        return self._h

    def close(self) -> None:
        """Frees the calibration (idempotent)."""
        h, self._h = self._h, None
        if h:
            _native.lib().cdm_calibration_free(h)

    def __repr__(self) -> str:
        return "<cdm.Calibration %s%s>" % (self.source, " closed" if self._h is None else "")

    def position(self, lengths: Iterable[float]) -> Tuple[float, float, float]:
        """The holder position (x, y, z) in mm whose predicted readings best match
        `lengths` (4 nominal-scale pot readings, mm). CdmError CDM_ERR_NUMERIC
        when there is no solution."""
        h = self._handle("cdm_calibration_position")
        inp = _vector(lengths, 4, "Calibration.position: lengths")
        out = (ctypes.c_double * 3)()
        rc = _native.lib().cdm_calibration_position(h, inp, out)
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_position")
        return (float(out[0]), float(out[1]), float(out[2]))

    def position_covariance(self, position: Iterable[float]) -> Tuple[Tuple[float, float, float], ...]:
        """The covariance (mm^2, 3 x 3, device frame) of the position this
        calibration gives at `position` (x, y, z) mm: its fitted parameters'
        uncertainty propagated to first order (experimental, since 1.2;
        cdm_calibration_position_covariance). The 1-sigma per axis is the
        square root of the diagonal. CdmError CDM_ERR_UNSUPPORTED when the
        file carries no covariance, CDM_ERR_NUMERIC outside the workspace."""
        h = self._handle("cdm_calibration_position_covariance")
        inp = _vector(position, 3, "Calibration.position_covariance: position")
        out = (ctypes.c_double * 9)()
        rc = _native.lib().cdm_calibration_position_covariance(h, inp, out)
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_position_covariance")
        return tuple((float(out[3 * r]), float(out[3 * r + 1]), float(out[3 * r + 2])) for r in range(3))

    def lengths(self, position: Iterable[float]) -> Tuple[float, float, float, float]:
        """The 4 readings (mm) the calibrated model predicts at position (x, y, z) mm."""
        h = self._handle("cdm_calibration_lengths")
        inp = _vector(position, 3, "Calibration.lengths: position")
        out = (ctypes.c_double * 4)()
        rc = _native.lib().cdm_calibration_lengths(h, inp, out)
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_lengths")
        return (float(out[0]), float(out[1]), float(out[2]), float(out[3]))

    @property
    def effects(self) -> List[str]:
        """Names of the physical effects in this calibration, in model order."""
        h = self._handle("cdm_calibration_effect_count")
        L = _native.lib()
        return [_native.text(L.cdm_calibration_effect_name(h, i))
                for i in range(L.cdm_calibration_effect_count(h))]
