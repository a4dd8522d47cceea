"""The model-debugging diagnosis (`cdm calib diagnose`) from Python."""
import ctypes
import json
import numbers
import os

from . import _native
from .constants import Error
from .errors import CdmError
from . import effects as _effects

try:
    import numpy as _np
except ImportError:  # numpy is optional: per-position data stay lists
    _np = None


def _is_number(v):
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _arrays(obj):
    """Lists of numbers (or rectangular lists of such lists) -> numpy arrays, recursively."""
    if isinstance(obj, dict):
        return {k: _arrays(v) for k, v in obj.items()}
    if isinstance(obj, list):
        if obj and all(_is_number(v) for v in obj):
            return _np.asarray(obj, dtype=float)
        if (obj and all(isinstance(v, list) and v and all(_is_number(x) for x in v) for v in obj)
                and len({len(v) for v in obj}) == 1):
            return _np.asarray(obj, dtype=float)
        return [_arrays(v) for v in obj]
    return obj


def diagnose(data_csv, device_json, effects=None, jig_tolerance_mm=None, progress=None, **options):
    """Runs cdm_diagnose and returns its result (docs/calibration.md gives the
    schema) as a dict. Under result["positions"], lists of numbers become numpy
    arrays when numpy is installed.

    effects           effect names to fit on top of the nominal model
    jig_tolerance_mm  the jig's positioning tolerance
    progress          progress(stage: str, fraction: float) -> truthy to cancel
    **options         any other option of cdm_diagnose (candidates=True,
                      per_position=True, calibration_out="calib.json", ...)"""
    return _run("cdm_diagnose", data_csv, device_json, effects, jig_tolerance_mm, progress, options)


def fit(data_csv, device_json, effects, jig_tolerance_mm=None, calibration_out=None, progress=None):
    """Runs cdm_fit (experimental, since 1.1): the calibration fit alone,
    without the diagnosis's candidates, review and validation. Returns
    {"effects": [{"name", "params": {p: {value, std, unit}}}], "fit": {...},
    "jig_tolerance_mm", "nominal_error_mm", "error_mm"}; writes the
    calibration atomically to calibration_out when given."""
    options = {}
    if calibration_out is not None:
        options["calibration_out"] = os.fspath(calibration_out)
    return _run("cdm_fit", data_csv, device_json, effects, jig_tolerance_mm, progress, options)


def _run(fn, data_csv, device_json, effects, jig_tolerance_mm, progress, options):
    if effects is not None:
        if isinstance(effects, str):
            effects = [effects]
        options["effects"] = list(effects)
    if jig_tolerance_mm is not None:
        options["jig_tolerance_mm"] = float(jig_tolerance_mm)
    options_json = json.dumps(options).encode("utf-8") if options else None

    raised = []
    cb = _native.cdm_progress_fn()  # NULL
    if progress is not None:
        def trampoline(_user, stage, fraction):
            try:
                return 1 if progress((stage or b"").decode("utf-8", "replace"), fraction) else 0
            except BaseException as e:  # cancel, and re-raise once back in Python
                raised.append(e)
                return 1
        cb = _native.cdm_progress_fn(trampoline)

    L = _native.lib()
    out = ctypes.c_void_p()
    _effects._take_errors()
    rc = getattr(L, fn)(_native.c_path(data_csv, "dataset path"), _native.c_path(device_json, "device path"),
                        options_json, cb, None, ctypes.byref(out))
    if rc < 0:
        err = _native.fail(rc, fn)
        L.cdm_free_string(out)
        if raised:
            raise raised[0]
        effect_errors = _effects._take_errors()
        if effect_errors:
            raise err from effect_errors[0][1]
        raise err
    try:
        if not out.value:
            raise CdmError(Error.CDM_ERR_INTERNAL, "%s returned CDM_OK and no result" % fn,
                                   function=fn)
        text = ctypes.string_at(out.value).decode("utf-8")
    finally:
        L.cdm_free_string(out)
    if raised:
        raise raised[0]
    # The library does not (yet) fail a diagnosis whose effect returned an
    # error: its numbers would be computed with unchanged readings. Say so.
    effect_errors = _effects._take_errors()
    if effect_errors:
        name, exc = effect_errors[0]
        raise CdmError(Error.CDM_ERR_INVALID_ARG, "user effect %r raised %s: %s (%d failed call(s)); the result "
                       "is not trustworthy" % (name, type(exc).__name__, exc, len(effect_errors)),
                       function=fn) from exc
    result = json.loads(text)
    if _np is not None and isinstance(result, dict) and "positions" in result:
        result["positions"] = _arrays(result["positions"])
    return result
