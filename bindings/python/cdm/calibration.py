"""Calibrations: load, corrected forward kinematics and its inverse."""
import ctypes
import math
import os

from . import _native
from .constants import Error
from .errors import CdmError


def _vector(values, n, what):
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

    def __init__(self, handle, source):
        self._h = handle
        self.source = source

    @classmethod
    def load(cls, path):
        """Loads a calibration JSON file; errors name the file, line and column."""
        path = os.fspath(path)
        h = ctypes.c_void_p()
        rc = _native.lib().cdm_calibration_load(_native.c_path(path, "calibration path"), ctypes.byref(h))
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_load")
        return cls(h, path)

    @classmethod
    def parse(cls, text):
        """The same from JSON text (str or bytes)."""
        data = text.encode("utf-8") if isinstance(text, str) else bytes(text)
        h = ctypes.c_void_p()
        rc = _native.lib().cdm_calibration_parse(data, len(data), ctypes.byref(h))
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_parse")
        return cls(h, "<text>")

    def _handle(self, function):
        if self._h is None:
            raise CdmError(Error.CDM_ERR_INVALID_ARG, "calibration %s is closed" % self.source, function=function)
        return self._h

    def close(self):
        h, self._h = self._h, None
        if h:
            _native.lib().cdm_calibration_free(h)

    def __repr__(self):
        return "<cdm.Calibration %s%s>" % (self.source, " closed" if self._h is None else "")

    def position(self, lengths):
        """The holder position (x, y, z) in mm whose predicted readings best match
        `lengths` (4 nominal-scale pot readings, mm). CdmError CDM_ERR_NUMERIC
        when there is no solution."""
        h = self._handle("cdm_calibration_position")
        inp = _vector(lengths, 4, "Calibration.position: lengths")
        out = (ctypes.c_double * 3)()
        rc = _native.lib().cdm_calibration_position(h, inp, out)
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_position")
        return tuple(out)

    def lengths(self, position):
        """The 4 readings (mm) the calibrated model predicts at position (x, y, z) mm."""
        h = self._handle("cdm_calibration_lengths")
        inp = _vector(position, 3, "Calibration.lengths: position")
        out = (ctypes.c_double * 4)()
        rc = _native.lib().cdm_calibration_lengths(h, inp, out)
        if rc < 0:
            raise _native.fail(rc, "cdm_calibration_lengths")
        return tuple(out)

    @property
    def effects(self):
        """Names of the physical effects in this calibration, in model order."""
        h = self._handle("cdm_calibration_effect_count")
        L = _native.lib()
        return [L.cdm_calibration_effect_name(h, i).decode("utf-8")
                for i in range(L.cdm_calibration_effect_count(h))]
