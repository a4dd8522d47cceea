"""User-defined physical effects (CDM_EXPERIMENTAL): register Python code as an
effect that every later fit, diagnosis and calibration load can use."""
from __future__ import annotations

import ctypes
import math
import os
import re
import threading
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple, Union

from . import _native
from .constants import EffectStage, Error

try:
    import numpy as _np
except ImportError:  # numpy is optional
    _np = None  # type: ignore[assignment]

# name -> _Registration. Holds every object native code may still reach
# (the apply trampoline, the parameter arrays).
_registry: Dict[str, _Registration] = {}
# Registrations removed by unregister_effect. A model or calibration built
# while the effect was registered keeps its description, and with it the
# trampoline's address, for as long as it lives; freeing the trampoline
# would leave it a dangling pointer. They are kept for the process's life
# (a few hundred bytes each).
_retired: List[_Registration] = []
_registry_lock = threading.Lock()


class _Registration:
    """One Python effect and every object native code may reach through it."""

    def __init__(self, name: str, n: int, apply: Callable[..., Any]) -> None:
        self.name = name
        self.n = n
        self.apply = apply
        self.errors: List[Tuple[str, BaseException]] = []  # exceptions raised by apply, newest last (capped)
        self.keep: List[Any] = []    # ctypes objects native code points into

    def _guarded(self, body: Callable[..., None], *args: Any) -> int:
        # Runs body(*args) for native code: 0 on success, an error code
        # (the exception kept in self.errors) otherwise.
        try:
            body(*args)
            return 0
        except ArithmeticError as e:
            self._record(e)
            return int(Error.CDM_ERR_NUMERIC)
        except BaseException as e:  # never let an exception unwind into C
            self._record(e)
            return int(Error.CDM_ERR_INTERNAL)

    def trampoline(self, _user: Any, params_p: Any, position_p: Any, readings_p: Any) -> int:
        return self._guarded(self._one, params_p, position_p, readings_p)

    def batch_trampoline(self, _user: Any, params_p: Any, n: int, positions_p: Any, readings_p: Any) -> int:
        # vectorized=True: every position at once (numpy is checked at registration).
        return self._guarded(self._batch, params_p, n, positions_p, readings_p)

    def _one(self, params_p: Any, position_p: Any, readings_p: Any) -> None:
        params: Any
        position: Any
        readings: Any
        if _np is not None:
            params = _np.ctypeslib.as_array(params_p, shape=(self.n,)).copy() if self.n else _np.zeros(0)
            position = _np.ctypeslib.as_array(position_p, shape=(3,)).copy()
            readings = _np.ctypeslib.as_array(readings_p, shape=(4,))  # a view: changed in place
        else:
            params = tuple(params_p[i] for i in range(self.n))
            position = tuple(position_p[i] for i in range(3))
            readings = ctypes.cast(readings_p, ctypes.POINTER(ctypes.c_double * 4)).contents
        self.apply(params, position, readings)

    def _batch(self, params_p: Any, n: int, positions_p: Any, readings_p: Any) -> None:
        if n == 0:
            return
        params = _np.ctypeslib.as_array(params_p, shape=(self.n,)).copy() if self.n else _np.zeros(0)
        positions = _np.ctypeslib.as_array(positions_p, shape=(n, 3)).copy()
        readings = _np.ctypeslib.as_array(readings_p, shape=(n, 4))  # a view: changed in place
        out = self.apply(params, positions, readings)
        if out is not None and out is not readings:
            out = _np.asarray(out, dtype=float)
            if out.shape != (n, 4):
                raise ValueError("effect %r: apply returned shape %r, expected (%d, 4)" % (self.name, out.shape, n))
            readings[...] = out

    def geom_trampoline(self, _user: Any, params_p: Any, n: int, ctx_p: Any, values_p: Any) -> int:
        # geometry=True (since 1.2): the positions with the cables' geometry.
        return self._guarded(self._geom, params_p, n, ctx_p, values_p)

    def _geom(self, params_p: Any, n: int, ctx_p: Any, values_p: Any) -> None:
        if n == 0:
            return
        c = ctx_p.contents
        params = _np.ctypeslib.as_array(params_p, shape=(self.n,)).copy() if self.n else _np.zeros(0)

        def arr(p: Any, shape: Tuple[int, ...]) -> Any:
            return _np.ctypeslib.as_array(p, shape=shape).copy()
        geom = EffectGeometry(
            stage="path" if c.stage == int(EffectStage.CDM_EFFECT_STAGE_PATH) else "reading",
            positions=arr(c.positions_mm, (n, 3)), t_s=arr(c.t_s, (n,)), anchors=arr(c.anchors_mm, (n, 4, 3)),
            holders=arr(c.holders_mm, (n, 4, 3)), unit=arr(c.unit, (n, 4, 3)), chord=arr(c.chord_mm, (n, 4)))
        values = _np.ctypeslib.as_array(values_p, shape=(n, 4))  # a view: changed in place
        out = self.apply(params, geom, values)
        if out is not None and out is not values:
            out = _np.asarray(out, dtype=float)
            if out.shape != (n, 4):
                raise ValueError("effect %r: apply returned shape %r, expected (%d, 4)" % (self.name, out.shape, n))
            values[...] = out

    def _record(self, e: BaseException) -> None:
        self.errors.append((self.name, e))
        del self.errors[:-10]


class EffectGeometry:
    """What a geometry-aware effect (register_effect(..., geometry=True))
    gets besides its parameters and values, for n positions (copies; device
    frame, mm):

    stage      "path" (values are the cables' lengths before the pot's
               transfer) or "reading" (values are the readings)
    positions  (n, 3) the holder centre
    t_s        (n,) acquisition time, s since the session's start (0 live)
    anchors    (n, 4, 3) each cable's anchor (exit point), after the
               model's geometry effects at their current values
    holders    (n, 4, 3) each cable's attachment point on the holder
    unit       (n, 4, 3) unit vector from anchor to holder point
    chord      (n, 4) straight distance from anchor to holder point
    """
    __slots__ = ("stage", "positions", "t_s", "anchors", "holders", "unit", "chord")

    def __init__(self, stage: str, positions: Any, t_s: Any, anchors: Any, holders: Any, unit: Any,
                 chord: Any) -> None:
        self.stage, self.positions, self.t_s = stage, positions, t_s
        self.anchors, self.holders, self.unit, self.chord = anchors, holders, unit, chord

    def __repr__(self) -> str:
        return "EffectGeometry(stage=%r, n=%d)" % (self.stage, len(self.t_s))


def _param_names(param_names: Iterable[str], name: str) -> List[str]:
    # Each name is a key of the calibration JSON and a column of the report:
    # an ASCII identifier, given once.
    if isinstance(param_names, (str, bytes)):
        raise TypeError("register_effect(%r): param_names must be a list of names, got the string %r"
                        % (name, param_names))
    names = list(param_names)
    for k, p in enumerate(names):
        if not isinstance(p, str):
            raise TypeError("register_effect(%r): parameter %d's name must be a str, got %r" % (name, k, p))
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", p):
            raise ValueError("register_effect(%r): parameter %d's name %r is not an identifier "
                             "([A-Za-z_][A-Za-z0-9_]*, non-empty, ASCII)" % (name, k, p))
    seen: set[str] = set()
    for p in names:
        if p in seen:
            raise ValueError("register_effect(%r): parameter name %r is given twice" % (name, p))
        seen.add(p)
    return names


def _units(units: Optional[Iterable[str]], n: int, name: str) -> Optional[List[bytes]]:
    if units is None:
        return None
    if isinstance(units, (str, bytes)):
        raise TypeError("register_effect(%r): units must be a list of one unit per parameter, got %r" % (name, units))
    unit_list = list(units)
    if len(unit_list) != n:
        raise ValueError("register_effect(%r): units has %d values for %d parameters" % (name, len(unit_list), n))
    out: List[bytes] = []
    for k, u in enumerate(unit_list):
        if not isinstance(u, str):
            raise TypeError("register_effect(%r): unit %d must be a str, got %r" % (name, k, u))
        try:
            raw = u.encode("utf-8")
        except UnicodeEncodeError as e:
            raise ValueError("register_effect(%r): unit %d (%r) is not valid UTF-8 text: %s" % (name, k, u, e)) from e
        if any(ch in u for ch in '"\\\x7f') or any(ord(ch) < 0x20 for ch in u):
            raise ValueError("register_effect(%r): unit %d (%r) has a control character, a quote or a backslash"
                             % (name, k, u))
        out.append(raw)
    return out


def _origin(apply: Callable[..., Any]) -> Optional[str]:
    # Where the effect comes from, for a calibration written with it: the
    # module that defines apply (a script run as __main__: its file).
    mod = getattr(apply, "__module__", None) or ""
    if mod == "__main__":
        import sys
        mod = getattr(sys.modules.get("__main__"), "__file__", None) or mod
    return "python:" + mod if mod else None


def _doubles(values: Optional[Iterable[float]], n: int, what: str, name: str) -> Any:
    if values is None:
        return None
    vals = [float(v) for v in values]
    if len(vals) != n:
        raise ValueError("register_effect(%r): %s has %d values for %d parameters" % (name, what, len(vals), n))
    if not all(math.isfinite(v) for v in vals):
        raise ValueError("register_effect(%r): %s must be finite, got %r" % (name, what, vals))
    return (ctypes.c_double * n)(*vals)


def register_effect(name: str, param_names: Iterable[str], param_scale: Optional[Iterable[float]],
                    apply: Callable[..., Any], doc: str = "", lower: Optional[Iterable[float]] = None,
                    upper: Optional[Iterable[float]] = None, initial: Optional[Iterable[float]] = None,
                    vectorized: bool = False, units: Optional[Iterable[str]] = None, stage: str = "reading",
                    geometry: bool = False, origin: Optional[str] = None) -> None:
    """Registers apply(params, position, readings) as the effect `name`.

    The model calls apply with the readings (4 values, mm) predicted by the
    nominal geometry and every effect before it; apply changes `readings` in
    place (a numpy view when numpy is installed, a ctypes array otherwise).
    params and position (mm, device frame) are copies. apply must be
    smooth in params and position: derivatives are central differences. An
    exception in apply fails the fit or diagnosis that called it.

    vectorized=True (since 1.1; needs numpy; the name scipy uses for the same
    choice): apply gets every position at once, params (k,), positions (n, 3)
    and readings (n, 4) numpy arrays, row i being position i, and changes
    readings in place or returns the new (n, 4) readings. The fit then calls
    it once per central-difference step instead of once per position and
    step (and the position solves of its error statistics once per
    iteration over every position): a few hundred times for a whole fit
    rather than tens of thousands. Row i must not depend on the other rows.
    Calls at one position (a pose, Calibration.lengths) pass n = 1.

    lower, upper: bounds per parameter; initial: where each parameter starts
    when the effect is added to a model (since 1.1; default 0 clamped into the
    bounds), so that a parameter entering non-linearly (a period, a centre)
    is fitted from a sensible value.

    Since 1.2 (needs numpy for geometry=True):
    units: one unit per parameter ("mm", "1/mm^2", "1"), shown by
    `cdm calib effects` and part of the effect's fingerprint.
    geometry=True: apply(params, geom, values) gets the cables' geometry,
    geom a cdm.EffectGeometry of n positions (positions (n, 3), t_s (n,),
    anchors, holders, unit (n, 4, 3), chord (n, 4)), and values (n, 4) to
    change in place or return: the cable lengths at stage "path", the
    readings at stage "reading". Called over every position at once where
    the fit evaluates many, with n = 1 for one position.
    stage: "reading" (default: after the pot's transfer, as without it) or
    "path" (the cable's length before the pot's transfer: sag, guides;
    cable_gain and the rest then act on the length it returns); "path"
    needs geometry=True.
    origin: where the effect comes from, recorded in a calibration written
    with it so that loading one without it names what to import (default
    "python:" and apply's module).
    Parameter names must be identifiers ([A-Za-z_][A-Za-z0-9_]*), each
    given once."""
    if not isinstance(name, str) or not re.fullmatch(r"[a-z0-9_]+", name):
        raise ValueError("register_effect: name must match [a-z0-9_]+, got %r" % (name,))
    if not callable(apply):
        raise TypeError("register_effect(%r): apply must be callable" % name)
    if (vectorized or geometry) and _np is None:
        raise ImportError("register_effect(%r, %s=True) needs numpy (pip install numpy)"
                          % (name, "geometry" if geometry else "vectorized"))
    stages = {"reading": EffectStage.CDM_EFFECT_STAGE_READING, "path": EffectStage.CDM_EFFECT_STAGE_PATH}
    if stage not in stages:
        raise ValueError("register_effect(%r): stage must be \"reading\" or \"path\", got %r" % (name, stage))
    if stage == "path" and not geometry:
        raise ValueError("register_effect(%r): stage=\"path\" needs geometry=True (the callback gets the cables' "
                         "lengths with their geometry)" % name)
    if geometry and vectorized:
        raise ValueError("register_effect(%r): geometry=True is always called on arrays; drop vectorized=True" % name)
    names = _param_names(param_names, name)
    n = len(names)
    units_raw = _units(units, n, name)
    if origin is None:
        origin = _origin(apply)
    reg = _Registration(name, n, apply)
    scale = _doubles(param_scale, n, "param_scale", name)
    if scale is not None and any(s <= 0 for s in scale):
        raise ValueError("register_effect(%r): param_scale must be > 0, got %r" % (name, list(scale)))
    lo = _doubles(lower, n, "lower", name)
    hi = _doubles(upper, n, "upper", name)
    init = _doubles(initial, n, "initial", name)
    names_c = (ctypes.c_char_p * max(n, 1))(*[p.encode("utf-8") for p in names])
    # One function, registered as apply or as apply_batch: the library calls
    # apply_batch with n = 1 where it needs one position.
    if geometry:
        fn = _native.cdm_effect_apply_geom_fn(reg.geom_trampoline)
    elif vectorized:
        fn = _native.cdm_effect_apply_batch_fn(reg.batch_trampoline)
    else:
        fn = _native.cdm_effect_apply_fn(reg.trampoline)
    d = _native.cdm_effect_def()
    d.n_params = n
    d.name = name.encode("utf-8")
    d.doc = doc.encode("utf-8")
    d.param_names = names_c
    d.param_scale = scale if scale is not None else (ctypes.c_double * max(n, 1))(*([1.0] * n))
    d.lower = lo
    d.upper = hi
    if geometry:
        d.apply_geom = fn
    elif vectorized:
        d.apply_batch = fn
    else:
        d.apply = fn
    d.user = None
    d.initial = init
    units_c: Any = None
    if units_raw is not None:
        units_c = (ctypes.c_char_p * max(n, 1))(*units_raw)
        d.param_units = units_c
    d.stage = int(stages[stage])
    d.origin = origin.encode("utf-8") if origin else None
    reg.keep = [fn, names_c, d.param_scale, lo, hi, init, units_c, d]
    with _registry_lock:
        if name in _registry:
            raise ValueError("register_effect: %r is already registered from Python; unregister it first" % name)
        rc = _native.lib().cdm_effect_register(ctypes.byref(d))
        if rc < 0:
            raise _native.fail(rc, "cdm_effect_register")
        _registry[name] = reg


def unregister_effect(name: str) -> None:
    """Removes a user effect registered with register_effect (or by a plugin)."""
    with _registry_lock:
        rc = _native.lib().cdm_effect_unregister(_native.c_path(name, "effect name"))
        if rc < 0:
            raise _native.fail(rc, "cdm_effect_unregister")
        reg = _registry.pop(name, None)
        if reg is not None:
            _retired.append(reg)


def load_plugin(path: Union[str, os.PathLike[str]]) -> None:
    """Loads a shared object exporting cdm_plugin_init and registers its effects."""
    rc = _native.lib().cdm_effect_load_plugin(os.fspath(path).encode("utf-8"))
    if rc < 0:
        raise _native.fail(rc, "cdm_effect_load_plugin")


def effect_names() -> List[str]:
    """Every effect known to the library: built-in first, then user ones."""
    L = _native.lib()
    return [_native.text(L.cdm_effect_name(i)) for i in range(L.cdm_effect_count())]


def _take_errors() -> List[Tuple[str, BaseException]]:
    """(effect name, exception) raised by Python effects since the last call (for diagnose)."""
    out: List[Tuple[str, BaseException]] = []
    with _registry_lock:
        for reg in _registry.values():
            out += reg.errors
            reg.errors = []
    return out
