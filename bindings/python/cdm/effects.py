"""User-defined physical effects (CDM_EXPERIMENTAL): register Python code as an
effect that every later fit, diagnosis and calibration load can use."""
import ctypes
import math
import re
import threading

from . import _native
from .constants import Error

try:
    import numpy as _np
except ImportError:  # numpy is optional
    _np = None  # type: ignore[assignment]

# name -> _Registration. Holds every object native code may still reach
# (the apply trampoline, the parameter arrays).
_registry: dict = {}
# Registrations removed by unregister_effect. A model or calibration built
# while the effect was registered keeps its description, and with it the
# trampoline's address, for as long as it lives; freeing the trampoline
# would leave it a dangling pointer. They are kept for the process's life
# (a few hundred bytes each).
_retired: list = []
_registry_lock = threading.Lock()


class _Registration:
    def __init__(self, name, n, apply):
        self.name = name
        self.n = n
        self.apply = apply
        self.errors = []  # exceptions raised by apply, newest last (capped)
        self.keep = []    # ctypes objects native code points into

    def _guarded(self, body, *args):
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

    def trampoline(self, _user, params_p, position_p, readings_p):
        return self._guarded(self._one, params_p, position_p, readings_p)

    def batch_trampoline(self, _user, params_p, n, positions_p, readings_p):
        # vectorized=True: every position at once (numpy is checked at registration).
        return self._guarded(self._batch, params_p, n, positions_p, readings_p)

    def _one(self, params_p, position_p, readings_p):
        if _np is not None:
            params = _np.ctypeslib.as_array(params_p, shape=(self.n,)).copy() if self.n else _np.zeros(0)
            position = _np.ctypeslib.as_array(position_p, shape=(3,)).copy()
            readings = _np.ctypeslib.as_array(readings_p, shape=(4,))  # a view: changed in place
        else:
            params = tuple(params_p[i] for i in range(self.n))
            position = tuple(position_p[i] for i in range(3))
            readings = ctypes.cast(readings_p, ctypes.POINTER(ctypes.c_double * 4)).contents
        self.apply(params, position, readings)

    def _batch(self, params_p, n, positions_p, readings_p):
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

    def _record(self, e):
        self.errors.append((self.name, e))
        del self.errors[:-10]


def _doubles(values, n, what, name):
    if values is None:
        return None
    vals = [float(v) for v in values]
    if len(vals) != n:
        raise ValueError("register_effect(%r): %s has %d values for %d parameters" % (name, what, len(vals), n))
    if not all(math.isfinite(v) for v in vals):
        raise ValueError("register_effect(%r): %s must be finite, got %r" % (name, what, vals))
    return (ctypes.c_double * n)(*vals)


def register_effect(name, param_names, param_scale, apply, doc="", lower=None, upper=None, initial=None,
                    vectorized=False):
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
    is fitted from a sensible value."""
    if not isinstance(name, str) or not re.fullmatch(r"[a-z0-9_]+", name):
        raise ValueError("register_effect: name must match [a-z0-9_]+, got %r" % (name,))
    if not callable(apply):
        raise TypeError("register_effect(%r): apply must be callable" % name)
    if vectorized and _np is None:
        raise ImportError("register_effect(%r, vectorized=True) needs numpy (pip install numpy)" % name)
    param_names = [str(p) for p in param_names]
    n = len(param_names)
    reg = _Registration(name, n, apply)
    scale = _doubles(param_scale, n, "param_scale", name)
    if scale is not None and any(s <= 0 for s in scale):
        raise ValueError("register_effect(%r): param_scale must be > 0, got %r" % (name, list(scale)))
    lo = _doubles(lower, n, "lower", name)
    hi = _doubles(upper, n, "upper", name)
    init = _doubles(initial, n, "initial", name)
    names_c = (ctypes.c_char_p * max(n, 1))(*[p.encode("utf-8") for p in param_names])
    # One function, registered as apply or as apply_batch: the library calls
    # apply_batch with n = 1 where it needs one position.
    if vectorized:
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
    if vectorized:
        d.apply_batch = fn
    else:
        d.apply = fn
    d.user = None
    d.initial = init
    reg.keep = [fn, names_c, d.param_scale, lo, hi, init, d]
    with _registry_lock:
        if name in _registry:
            raise ValueError("register_effect: %r is already registered from Python; unregister it first" % name)
        rc = _native.lib().cdm_effect_register(ctypes.byref(d))
        if rc < 0:
            raise _native.fail(rc, "cdm_effect_register")
        _registry[name] = reg


def unregister_effect(name):
    """Removes a user effect registered with register_effect (or by a plugin)."""
    with _registry_lock:
        rc = _native.lib().cdm_effect_unregister(_native.c_path(name, "effect name"))
        if rc < 0:
            raise _native.fail(rc, "cdm_effect_unregister")
        reg = _registry.pop(name, None)
        if reg is not None:
            _retired.append(reg)


def load_plugin(path):
    """Loads a shared object exporting cdm_plugin_init and registers its effects."""
    import os
    rc = _native.lib().cdm_effect_load_plugin(os.fspath(path).encode("utf-8"))
    if rc < 0:
        raise _native.fail(rc, "cdm_effect_load_plugin")


def effect_names():
    """Every effect known to the library: built-in first, then user ones."""
    L = _native.lib()
    return [L.cdm_effect_name(i).decode("utf-8") for i in range(L.cdm_effect_count())]


def _take_errors():
    """(effect name, exception) raised by Python effects since the last call (for diagnose)."""
    out = []
    with _registry_lock:
        for reg in _registry.values():
            out += reg.errors
            reg.errors = []
    return out
