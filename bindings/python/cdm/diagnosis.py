"""The model-debugging diagnosis (`cdm calib diagnose`) from Python."""
import ctypes
import json
import numbers
import os
import signal
import threading
from typing import Any, Callable, Dict, Iterable, List, Optional, Union

from . import _native
from .constants import Error
from .errors import CdmError
from . import effects as _effects

try:
    import numpy as _np
except ImportError:  # numpy is optional: per-position data stay lists
    _np = None  # type: ignore[assignment]


def _is_number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _whole(name: str, v: Any) -> int:
    """`v` as an int when it is a whole number (2 or 2.0; not True, 2.5 or
    "2"): a count the library takes as an integer is never truncated."""
    if isinstance(v, numbers.Integral) and not isinstance(v, bool):
        return int(v)
    if _is_number(v) and float(v).is_integer():
        return int(v)
    raise TypeError(f"{name} must be a whole number, not {v!r}")


def _effect_names(effects: Union[str, Iterable[str]]) -> List[str]:
    """A list of names, or one string of comma-separated names as the `cdm`
    command takes them ("exit_pulley,cable_gain")."""
    if isinstance(effects, str):
        return [e for e in effects.split(",") if e]
    return list(effects)


def _finite_json(o: Dict[str, Any], function: str) -> bytes:
    """Options as JSON; a NaN or infinity anywhere is refused naming its key
    (JSON has none, and the library would only say the text is not JSON)."""
    def walk(v: Any, where: str) -> None:
        if isinstance(v, float) and not float("-inf") < v < float("inf"):
            raise ValueError(f"{function}: {where} is {v!r}, not a finite number")
        if isinstance(v, dict):
            for k, x in v.items():
                walk(x, f"{where}.{k}" if where else str(k))
        elif isinstance(v, (list, tuple)):
            for i, x in enumerate(v):
                walk(x, f"{where}[{i}]")
    walk(o, "")
    return json.dumps(o).encode("utf-8")


PathLike = Union[str, "os.PathLike[str]"]
Progress = Callable[[str, float], Any]

__all__ = ["Diagnosis", "diagnose", "fit", "load_diagnosis"]


class Diagnosis(Dict[str, Any]):
    """What cdm.diagnose() returns: the library's result (docs/calibration.md
    gives the schema) as a dict, with the per-position data under
    ["positions"] as numpy arrays when numpy is installed. Saved and loaded
    as the same JSON `cdm calib diagnose --json` writes."""

    @property
    def verdict(self) -> str:
        """The diagnosis's one-line verdict ("" when absent)."""
        return str(self.get("verdict", ""))

    def to_json(self, path: Optional[PathLike] = None, indent: Optional[int] = None) -> str:
        """The JSON text (arrays back to lists); with `path`, also written
        there atomically (libcdm's writer: an exclusive temporary, fsync,
        rename; the old file survives any failure)."""
        text = json.dumps(_plain(self), indent=indent) + "\n"
        if path is not None:
            data = text.encode("utf-8")
            L = _native.lib()
            rc = L.cdm_write_file_atomic(_native.c_path(path, "path"), data, len(data), None, 0)
            _native.check(rc, "cdm_write_file_atomic")
        return text


def load_diagnosis(path: PathLike) -> Diagnosis:
    """A Diagnosis saved by Diagnosis.to_json() or `cdm calib diagnose --json`."""
    with open(os.fspath(path), encoding="utf-8") as f:
        result = json.load(f)
    if not isinstance(result, dict) or "verdict" not in result:
        raise ValueError("%s: not a cdm diagnosis (no \"verdict\")" % os.fspath(path))
    return _as_diagnosis(result)


def _as_diagnosis(result: Dict[str, Any]) -> Diagnosis:
    d = Diagnosis(result)
    if _np is not None and "positions" in d:
        d["positions"] = _arrays(d["positions"])
    return d


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if _np is not None and isinstance(obj, _np.ndarray):
        return obj.tolist()
    return obj


def _arrays(obj: Any) -> Any:
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


def accuracy_map(result: Dict[str, Any]) -> Dict[str, Any]:
    """The accuracy map of a diagnosis or a fit (its "accuracy_map") as numpy
    arrays over the grid's N points (device frame, mm): "x", "y", "z" (N),
    "sigma" (N x 3, 1-sigma per axis), "radius95" (N, the 95 % ellipsoid's
    longest semi-axis), "cov" (N x 3 x 3, mm^2), "inside" and "placed" (N,
    bool: within the jig's volume; placed by the model), NaN where a point
    is not placed; "levels" (the x levels), "ny", "nz" (points per level,
    y fastest) and "summary" as in the JSON. Needs numpy."""
    if _np is None:
        raise ImportError("cdm.accuracy_map needs numpy")
    a = result.get("accuracy_map") if isinstance(result, dict) else None
    if not isinstance(a, dict) or "grid" not in a:
        why = a.get("error") if isinstance(a, dict) else None
        raise ValueError("no accuracy map in this result" + (": %s" % why if why else ""))
    g = a["grid"]

    def rows(key: str, width: int) -> Any:
        return _np.asarray([v if v is not None else [float("nan")] * width for v in a[key]], dtype=float)
    c6 = rows("cov_mm2", 6)
    cov = _np.empty((len(c6), 3, 3))
    for k, (r, q) in enumerate([(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]):
        cov[:, r, q] = cov[:, q, r] = c6[:, k]
    return {"x": _np.asarray(g["x_mm"], dtype=float), "y": _np.asarray(g["y_mm"], dtype=float),
            "z": _np.asarray(g["z_mm"], dtype=float), "sigma": rows("sigma_mm", 3),
            "radius95": _np.asarray([v if v is not None else float("nan") for v in a["radius95_mm"]], dtype=float),
            "cov": cov, "inside": _np.asarray(a["inside"], dtype=bool), "placed": _np.asarray(a["placed"], dtype=bool),
            "levels": _np.asarray(g["levels_mm"], dtype=float), "ny": int(g["ny"]), "nz": int(g["nz"]),
            "summary": a["summary"]}


def diagnose(data_csv: PathLike, device_json: PathLike, effects: Optional[Union[str, Iterable[str]]] = None,
             jig_tolerance_mm: Optional[float] = None, progress: Optional[Progress] = None,
             **options: Any) -> Diagnosis:
    """Runs cdm_diagnose and returns its result (docs/calibration.md gives the
    schema) as a dict. Under result["positions"], lists of numbers become numpy
    arrays when numpy is installed.

    effects           effect names to fit on top of the nominal model
    jig_tolerance_mm  the jig's positioning tolerance
    progress          progress(stage: str, fraction: float) -> truthy to cancel
    **options         any other option of cdm_diagnose (candidates=True,
                      per_position=True, outliers=True, calibration_out="calib.json", ...)"""
    return _as_diagnosis(_run("cdm_diagnose", data_csv, device_json, effects, jig_tolerance_mm, progress, options))


def fit(data_csv: PathLike, device_json: PathLike, effects: Union[str, Iterable[str]],
        jig_tolerance_mm: Optional[float] = None, calibration_out: Optional[PathLike] = None,
        progress: Optional[Progress] = None, outliers: bool = True) -> Dict[str, Any]:
    """Runs cdm_fit (experimental, since 1.1): the calibration fit alone,
    without the diagnosis's candidates, review and validation. Returns
    {"effects": [{"name", "params": {p: {value, std, unit}}}], "fit": {...},
    "jig_tolerance_mm", "nominal_error_mm", "error_mm", "glitches",
    "outliers"}; writes the calibration atomically to calibration_out when
    given. outliers=False keeps the positions the fitted model and their
    neighbours both disown (by default set aside, and the fit run again)."""
    options: Dict[str, Any] = {"outliers": bool(outliers)}
    if calibration_out is not None:
        options["calibration_out"] = os.fspath(calibration_out)
    return _run("cdm_fit", data_csv, device_json, effects, jig_tolerance_mm, progress, options)


def check(data_csv: PathLike, calibration: PathLike, jig_tolerance_mm: Optional[float] = None,
          max_error_mm: Optional[float] = None, progress: Optional[Progress] = None) -> Dict[str, Any]:
    """Runs cdm_check (experimental, since 1.2): the calibration (a file of
    `cdm calib fit --out` or fit(calibration_out=...)) applied as it is to
    another jig session of the same device, only the jig placed anew (a jig
    is placed by hand at every session). Returns {"effects", "positions",
    "jig", "error_mm" (per sample, the seed's Table 1), "position_error_mm"
    (each position's mean error: the calibration's systematic error),
    "nominal_error_mm", "calibration_fit", "failing", "model_check" (holds,
    chi2_per_dof, ..., text), "reading_noise_mm", "glitches"}.
    max_error_mm lists the positions whose mean error is longer."""
    options: Dict[str, Any] = {}
    if max_error_mm is not None:
        options["max_error_mm"] = float(max_error_mm)
    return _run("cdm_check", data_csv, calibration, None, jig_tolerance_mm, progress, options,
                second="calibration path")


def plan(positions: int, samples: int = 100, holes: int = 25, pitch_mm: float = 5.0,
         heights_mm: Optional[Iterable[float]] = None, effects: Optional[Union[str, Iterable[str]]] = None,
         device_json: Optional[PathLike] = None, **options: Any) -> Dict[str, Any]:
    """Runs cdm_plan (experimental, since 1.2): which `positions` of the plate
    (holes x heights) to measure, from the geometry and the catalogue alone.
    Returns {"positions": [[x_ref, y_ref, z_ref, samples], ...] in walking
    order, "points", "predicted_sigma_mm": {plan, whole_plate},
    "detectability": [...], ...}; `effects` plans for that model instead of
    the catalogue; **options: noise_mm, jig_tolerance_mm, alpha, power,
    measured (positions measured already: the plan goes on from them) and
    allowed (the only positions it may choose), each a list of [x, y, z]."""
    o: Dict[str, Any] = {"positions": _whole("positions", positions), "samples": _whole("samples", samples),
                         "holes": _whole("holes", holes), "pitch_mm": float(pitch_mm), **options}
    if heights_mm is not None:
        if isinstance(heights_mm, (str, bytes)):
            raise TypeError(f"heights_mm must be numbers (mm), e.g. [30, 40, 50], not {heights_mm!r}")
        o["heights_mm"] = [float(h) for h in heights_mm]
    if effects is not None:
        o["effects"] = _effect_names(effects)
    if device_json is not None:
        o["device"] = os.fspath(device_json)
    L = _native.lib()
    out = ctypes.c_void_p()
    rc: int = L.cdm_plan(_finite_json(o, "cdm.plan"), _native.cdm_progress_fn(), None, ctypes.byref(out))
    if rc < 0:
        raise _native.fail(rc, "cdm_plan")
    try:
        if not out.value:
            raise CdmError(Error.CDM_ERR_INTERNAL, "cdm_plan returned CDM_OK and no result", function="cdm_plan")
        text = ctypes.string_at(out.value).decode("utf-8")
    finally:
        L.cdm_free_string(out)
    result: Dict[str, Any] = json.loads(text)
    return result


def _run(fn: str, data_csv: PathLike, device_json: PathLike, effects: Optional[Union[str, Iterable[str]]],
         jig_tolerance_mm: Optional[float], progress: Optional[Progress], options: Dict[str, Any],
         second: str = "device path") -> Dict[str, Any]:
    if effects is not None:
        options["effects"] = _effect_names(effects)
    if jig_tolerance_mm is not None:
        options["jig_tolerance_mm"] = float(jig_tolerance_mm)
    options_json = _finite_json(options, fn) if options else None

    # Ctrl-C cancels a long run: while the library works, SIGINT (in the
    # main thread, with Python's default handler) only sets a flag; the
    # progress callback, which the library calls between fit iterations,
    # cancels on it, and KeyboardInterrupt is raised once back in Python. A
    # KeyboardInterrupt raised inside a ctypes callback would be swallowed.
    raised: List[BaseException] = []
    interrupted: List[int] = []

    def trampoline(_user: Any, stage: Optional[bytes], fraction: float) -> int:
        if interrupted:
            return 1
        try:
            if progress is None:
                return 0
            return 1 if progress((stage or b"").decode("utf-8", "replace"), fraction) else 0
        except BaseException as e:  # cancel, and re-raise once back in Python
            raised.append(e)
            return 1
    cb = _native.cdm_progress_fn(trampoline)

    L = _native.lib()
    out = ctypes.c_void_p()
    _effects._take_errors()
    data_path, device_path = _native.c_path(data_csv, "dataset path"), _native.c_path(device_json, second)
    previous = None
    if (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        previous = signal.signal(signal.SIGINT, lambda signum, frame: interrupted.append(signum))
    try:
        rc: int = getattr(L, fn)(data_path, device_path, options_json, cb, None, ctypes.byref(out))
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
    if interrupted:
        if out.value:
            L.cdm_free_string(out)
        raise KeyboardInterrupt
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
    result: Any = json.loads(text)
    if not isinstance(result, dict):
        raise CdmError(Error.CDM_ERR_INTERNAL, "%s returned %s, not a JSON object" % (fn, type(result).__name__),
                       function=fn)
    return result
