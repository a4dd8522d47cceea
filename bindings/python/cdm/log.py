"""libcdm's messages into Python's logging (cdm_set_log_fn, since 1.1).

    import logging, cdm
    logging.basicConfig(level=logging.INFO)
    cdm.log.to_python()            # logger "cdm"; libcdm's levels map to logging's

Opt-in: the library calls the hook from its reader threads, so it is
removed again at interpreter exit (atexit), before Python goes away.
"""
import atexit
import logging
import threading
from typing import Optional

from . import _native

__all__ = ["to_python", "stop"]

_LEVELS = {0: logging.DEBUG, 1: logging.INFO, 2: logging.WARNING, 3: logging.ERROR}
_lock = threading.Lock()
_installed: Optional[object] = None  # the ctypes callback, kept alive while installed
_registered_atexit = False


def to_python(logger: Optional[logging.Logger] = None) -> None:
    """Routes every libcdm message to `logger` (default logging.getLogger("cdm"))."""
    global _installed, _registered_atexit
    target = logger or logging.getLogger("cdm")

    def hook(_user: object, level: int, message: Optional[bytes]) -> None:
        target.log(_LEVELS.get(level, logging.ERROR), "%s", _native.text(message))

    cb = _native.cdm_log_fn(hook)
    with _lock:
        _native.lib().cdm_set_log_fn(cb, None)
        _installed = cb
        if not _registered_atexit:
            atexit.register(stop)
            _registered_atexit = True


def stop() -> None:
    """Stops routing libcdm's messages (the library's default: none)."""
    global _installed
    with _lock:
        if _installed is not None:
            _native.lib().cdm_set_log_fn(_native.cdm_log_fn(), None)
            _installed = None
