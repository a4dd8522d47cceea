"""Hot-plug: arrivals and departures of masters as they happen (cdm_watch,
experimental in the C API: docs/reliability.md, "Hot-plug").

    import cdm
    def told(kind, info):
        print(kind, info.uri, info.serial)      # "arrived"/"left", cdm.DeviceInfo
    with cdm.watch(told):
        time.sleep(60)
"""
import ctypes
import threading
from typing import Any, Callable, List, Optional

from . import _native
from .constants import Error, WatchFlag, WatchKind
from .records import DeviceInfo
from .errors import CdmError

KIND_NAMES = {WatchKind.CDM_WATCH_ARRIVED: "arrived", WatchKind.CDM_WATCH_LEFT: "left"}


class Watcher(_native.Closing):
    """A running watch. close() (idempotent; also on leaving a with block)
    stops it: when close() returns the callback is not running and will not
    run again. close() from inside the callback raises RuntimeError (it would
    join the thread it runs on); the watch goes on."""

    def __init__(self, handle: ctypes.c_void_p, callback: Any, callback_thread: List[int]) -> None:
        self._h: Optional[ctypes.c_void_p] = handle
        # The ctypes function object must outlive the native watcher: its
        # thread calls it until cdm_watch_free returns.
        self._callback = callback
        self._callback_thread = callback_thread  # [ident] of the watcher's thread, once it called
        self._lock = threading.Lock()

    def close(self) -> None:
        """Stops the watch (idempotent): the callback does not run after this returns."""
        if self._callback_thread and self._callback_thread[0] == threading.get_ident():
            raise RuntimeError("cdm.Watcher.close() from its own callback: it would join the thread it runs on")
        with self._lock:
            h, self._h = self._h, None
        if h:
            _native.lib().cdm_watch_free(h)
            self._callback = None

    @property
    def closed(self) -> bool:
        """close() was called."""
        return self._h is None

    def __repr__(self) -> str:
        return "<cdm.Watcher%s>" % (" closed" if self.closed else "")


def watch(callback: Callable[[str, DeviceInfo], Any],
          enumerate: bool = True) -> Watcher:  # noqa: A002 - mirrors CDM_WATCH_ENUMERATE
    """Calls callback(kind, info) for every master that arrives or leaves:
    kind is "arrived" or "left", info a cdm.DeviceInfo (for "left", what was
    known when it arrived). With enumerate (the default), the masters already
    connected come first as "arrived".

    The callback runs on the watcher's own thread, one event at a time; an
    exception it raises is printed (ctypes cannot carry it into C) and the
    watch goes on. Returns a Watcher; raises CdmError (CDM_ERR_UNSUPPORTED
    where udev's monitor is refused)."""
    if not callable(callback):
        raise TypeError("watch: callback must be callable, got %r" % (callback,))

    callback_thread: List[int] = []

    def trampoline(_user: Any, event_p: Any) -> None:
        if not callback_thread:
            callback_thread.append(threading.get_ident())
        e = event_p.contents
        callback(KIND_NAMES.get(e.kind, "event %d" % e.kind), DeviceInfo._from_c(e.info.contents))

    fn = _native.cdm_watch_fn(trampoline)
    h = ctypes.c_void_p()
    flags = int(WatchFlag.CDM_WATCH_ENUMERATE) if enumerate else 0
    rc = _native.lib().cdm_watch(flags, fn, None, ctypes.byref(h))
    if rc < 0:
        raise _native.fail(rc, "cdm_watch")
    if not h.value:
        raise CdmError(Error.CDM_ERR_INTERNAL, "cdm_watch returned CDM_OK and no watcher", function="cdm_watch")
    return Watcher(h, fn, callback_thread)
