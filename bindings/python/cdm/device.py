"""Devices: open, poses, raw values, information, counters, stored calibration."""
from __future__ import annotations

import contextlib
import ctypes
import math
import threading
import os
import time
from typing import TYPE_CHECKING, Any, Callable, Iterator, List, Optional, Tuple, Union

from . import _native
from .constants import Error
from .errors import CdmError
from .records import DeviceInfo, Pose, Raw, Sample, Stats, check_units, pose_dtype, pose_record, sample_from_c

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from .calibration import Calibration

__all__ = ["Device", "DeviceInfo", "Pose", "Raw", "Sample", "Stats", "open", "enumerate_devices"]

# Return codes of cdm_get_pose / cdm_wait_pose / cdm_get_raw that come with a
# filled record: the pose is the last one, and its flags say why it is old.
_FILLED = (Error.CDM_ERR_STALE, Error.CDM_ERR_DISCONNECTED, Error.CDM_ERR_END_OF_STREAM)


class _CallbackState:
    """Shared by a device and its callbacks: which thread is the reader (the
    one the callbacks run on), and whether close() began (no user callback
    runs after it)."""

    def __init__(self) -> None:
        self.reader: Optional[int] = None
        self.closed = False


def _make_sample_callback(fn: Callable[[Sample], Any], units: str, state: _CallbackState) -> Any:
    def trampoline(_user: Any, sample_p: Any) -> None:
        state.reader = threading.get_ident()
        if state.closed:
            return
        fn(sample_from_c(sample_p.contents, units))
    return _native.cdm_sample_fn(trampoline)


class Device(_native.Closing):
    """An open master. Use as a context manager, or call close() (idempotent).

    Every method may be called from any thread, close() included, and from
    the device's own callbacks: the native handle stays alive while any call
    on it is in progress (a count of calls under a lock). close() wakes the
    threads blocked in wait_pose (they raise CdmError CDM_ERR_CLOSED, never
    return a pose), waits for the calls in progress to leave, then frees the
    handle. From the device's own callback, close() returns at once: no
    callback of this device runs after it, and the handle is freed on a
    helper thread once the callback has returned (docs/reliability.md,
    "Callbacks")."""

    def __init__(self, handle: ctypes.c_void_p, uri: Optional[str], callback: Any = None, units: str = "mm",
                 state: Optional[_CallbackState] = None) -> None:
        self._h: Optional[ctypes.c_void_p] = handle
        self.uri = uri
        #: "mm" or "m": the units of the poses this device returns (cdm.open(units=))
        self.units = check_units(units, "Device")
        # The ctypes callback object must outlive the native handle: the reader
        # thread calls it until cdm_close returns.
        self._callback = callback
        self._state = state or _CallbackState()
        self._lock = threading.Condition(threading.Lock())
        self._calls = 0  # native calls in progress on self._h

    # -- lifetime
    def close(self) -> None:
        """Closes the device (idempotent). Outside its callbacks, its reader
        thread has stopped when this returns; inside one, it stops once the
        callback has returned."""
        with self._lock:
            h = self._h
            if h is None or self._state.closed:
                return
            self._state.closed = True  # refuses new calls, silences the callbacks
        # Wakes the waiters (CDM_ERR_CLOSED); the handle stays valid.
        _native.lib().cdm_shutdown(h)
        if self._state.reader == threading.get_ident():
            # Inside this device's callback: cdm_close must not run before the
            # callback has returned into the library (the ctypes callback it
            # is running in must outlive that), so it runs on a helper thread,
            # which cdm_close's join makes wait for the callback's end.
            threading.Thread(target=self._finish_close, args=(h,), name="cdm-close", daemon=True).start()
            return
        self._finish_close(h)

    def _finish_close(self, h: ctypes.c_void_p) -> None:
        with self._lock:
            while self._calls:
                self._lock.wait()
            self._h = None
        _native.lib().cdm_close(h)
        self._callback = None

    @property
    def closed(self) -> bool:
        """close() was called."""
        return self._h is None or self._state.closed

    def __repr__(self) -> str:
        return "<cdm.Device %r%s>" % (self.uri, " closed" if self.closed else "")

    def _handle(self, function: str) -> ctypes.c_void_p:
        """The native handle, uncounted: for a caller that keeps the device
        open during its own native call (the package's calls use _use)."""
        if self._h is None or self._state.closed:
            raise CdmError(Error.CDM_ERR_INVALID_ARG, "device %r is closed" % (self.uri,), function=function)
        return self._h

    @contextlib.contextmanager
    def _use(self, function: str) -> Iterator[ctypes.c_void_p]:
        """The handle, counted as in use for the block: close() waits for it."""
        with self._lock:
            if self._h is None or self._state.closed:
                raise CdmError(Error.CDM_ERR_INVALID_ARG, "device %r is closed" % (self.uri,), function=function)
            self._calls += 1
            h = self._h
        try:
            yield h
        finally:
            with self._lock:
                self._calls -= 1
                if self._calls == 0:
                    self._lock.notify_all()

    def _fail(self, code: int, function: str) -> CdmError:
        L = _native.lib()
        detail = _native.text(L.cdm_thread_error())
        if not detail and not self.closed:
            detail = self.error_detail()
        return _native.fail(code, function, detail)

    # -- poses
    def get_pose(self) -> Pose:
        """The newest pose, without blocking.

        Raises CdmError(CDM_ERR_NO_DATA) before the first report (use
        wait_pose first). A stale, disconnected or ended stream is *not* an
        exception: the last pose is returned with its flags and .status set, as
        a control loop wants to hold the last command and look at the flags."""
        with self._use("cdm_get_pose") as h:
            p = _native.cdm_pose()
            rc = _native.lib().cdm_get_pose(h, ctypes.byref(p))
            if rc < 0 and rc not in _FILLED:
                raise self._fail(rc, "cdm_get_pose")
            return Pose._from_c(p, rc, self.units)

    # The C call waits in slices this long, so that Ctrl-C (handled by Python
    # between two foreign calls) interrupts a long wait within 0.1 s.
    _WAIT_SLICE_MS = 100

    def wait_pose(self, timeout: Optional[float] = 1.0, after: Optional[int] = None) -> Pose:
        """Blocks until a pose newer than `after` (a Pose.host_sequence; None:
        the newest pose at the time of the call) exists; returns at once if one
        already does, so a loop passing the last pose's host_sequence never
        misses one. timeout in seconds (None: no limit). Raises
        CdmError(CDM_ERR_TIMEOUT) when none came in time; otherwise returns
        like get_pose. Ctrl-C interrupts it."""
        with self._use("cdm_wait_pose_after") as h:
            if timeout is not None and (timeout < 0 or math.isnan(timeout)):
                raise ValueError("wait_pose: timeout must be >= 0 seconds or None, got %r" % (timeout,))
            if after is not None and (isinstance(after, bool) or not isinstance(after, int) or not 0 <= after < 2**64):
                raise ValueError("wait_pose: after must be a Pose.host_sequence (int in 0..2^64-1), got %r" % (after,))
            if timeout is not None and math.isinf(timeout):
                timeout = None  # no limit, as None says (a deadline at infinity overflows the clock's arithmetic)
            L = _native.lib()
            p = _native.cdm_pose()
            if after is None:
                L.cdm_get_pose(h, ctypes.byref(p))
                after = int(p.host_sequence)
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:
                left_ms = self._WAIT_SLICE_MS
                if deadline is not None:
                    left_ms = max(0, min(left_ms, int(math.ceil((deadline - time.monotonic()) * 1000.0))))
                rc = L.cdm_wait_pose_after(h, after, left_ms, ctypes.byref(p))
                waiting = rc in (Error.CDM_ERR_TIMEOUT, Error.CDM_ERR_DISCONNECTED)
                if not waiting or (deadline is not None and time.monotonic() >= deadline):
                    break
            if rc < 0 and rc not in _FILLED:
                raise self._fail(rc, "cdm_wait_pose_after")
            return Pose._from_c(p, rc, self.units)

    def get_raw(self) -> Raw:
        """Raw values of the newest report (same returns as get_pose)."""
        with self._use("cdm_get_raw") as h:
            r = _native.cdm_raw()
            rc = _native.lib().cdm_get_raw(h, ctypes.byref(r))
            if rc < 0 and rc not in _FILLED:
                raise self._fail(rc, "cdm_get_raw")
            return Raw._from_c(r, rc)

    # -- information
    def info(self) -> DeviceInfo:
        """What the device says about itself (cdm_get_info)."""
        with self._use("cdm_get_info") as h:
            i = _native.cdm_device_info()
            rc = _native.lib().cdm_get_info(h, ctypes.byref(i))
            if rc < 0:
                raise self._fail(rc, "cdm_get_info")
            return DeviceInfo._from_c(i)

    def stats(self) -> Stats:
        """The device's counters since it was opened (cdm_get_stats)."""
        with self._use("cdm_get_stats") as h:
            s = _native.cdm_stats()
            rc = _native.lib().cdm_get_stats(h, ctypes.byref(s))
            if rc < 0:
                raise self._fail(rc, "cdm_get_stats")
            return Stats(s.reports, s.malformed, s.dropped, s.out_of_workspace, s.reconnects, s.sequence_jumps,
                         s.out_of_order, s.replay_truncated_bytes, s.restarts)

    def error_detail(self) -> str:
        """The handle's last asynchronous problem (cdm_device_error), "" if none."""
        with self._use("cdm_device_error") as h:
            buf = ctypes.create_string_buffer(1024)
            rc = _native.lib().cdm_device_error(h, buf, len(buf))
            if rc < 0:
                return ""
            return buf.value.decode("utf-8", "replace")

    def set_stale_timeout(self, seconds: float) -> None:
        """Poses older than this are flagged stale; 0 restores the default (50 ms)."""
        us = int(round(seconds * 1e6))
        if not 0 <= us < 2**32:
            raise ValueError("set_stale_timeout: %r s is outside 0..4294 s" % (seconds,))
        with self._use("cdm_set_stale_timeout") as h:
            rc = _native.lib().cdm_set_stale_timeout(h, us)
            if rc < 0:
                raise self._fail(rc, "cdm_set_stale_timeout")

    # -- calibration
    def set_calibration(self, calibration: Optional[Calibration]) -> None:
        """Applies a cdm.Calibration to the poses from the next report on (the
        library copies it); None returns to the nominal model."""
        with self._use("cdm_set_calibration") as h:
            ch = None if calibration is None else calibration._handle("cdm_set_calibration")
            rc = _native.lib().cdm_set_calibration(h, ch)
            if rc < 0:
                raise self._fail(rc, "cdm_set_calibration")

    def read_stored_calibration(self) -> bytes:
        """The calibration bytes stored in the device (CdmError CDM_ERR_CRC when corrupt)."""
        with self._use("cdm_device_calibration_read") as h:
            L = _native.lib()
            n = ctypes.c_size_t(0)
            cap = 4096
            for _ in range(3):
                buf = ctypes.create_string_buffer(cap)
                rc = L.cdm_device_calibration_read(h, buf, cap, ctypes.byref(n))
                if rc == Error.CDM_ERR_NO_MEM and n.value > cap:
                    cap = n.value
                    continue
                if rc < 0:
                    raise self._fail(rc, "cdm_device_calibration_read")
                return buf.raw[:n.value]
            raise CdmError(Error.CDM_ERR_INTERNAL, "cdm_device_calibration_read kept asking for a bigger buffer",
                           function="cdm_device_calibration_read")

    def write_stored_calibration(self, data: Union[str, bytes]) -> None:
        """Stores bytes (typically a calibration JSON) in the device."""
        if isinstance(data, str):
            data = data.encode("utf-8")
        data = bytes(data)
        with self._use("cdm_device_calibration_write") as h:
            rc = _native.lib().cdm_device_calibration_write(h, data, len(data))
            if rc < 0:
                raise self._fail(rc, "cdm_device_calibration_write")

    # -- iteration and batches
    def __iter__(self) -> Iterator[Pose]:
        """`for pose in dev:` yields every pose newer than the one before
        (the first: newer than the newest when the loop starts), waiting as
        long as it takes; it ends at the end of a replay or when the device is
        closed. A pose the loop was too slow to see is skipped (host_sequence
        shows the gap): the device keeps the newest pose, not a queue (use
        on_sample for every report). Ctrl-C interrupts the wait."""
        after: Optional[int] = None
        while not self.closed:
            try:
                pose = self.wait_pose(None, after)
            except CdmError:
                if self.closed:
                    return
                raise
            if pose.status == Error.END_OF_STREAM and after is not None and pose.host_sequence <= after:
                return
            yield pose
            if pose.is_end_of_stream:
                return
            after = pose.host_sequence

    def read(self, n: int, timeout: Optional[float] = 1.0) -> npt.NDArray[np.void]:
        """The next n poses as a numpy structured array (dtype
        cdm.records.pose_dtype(): position, orientation, velocity, grip,
        buttons, flags, sequence, dropped, status, host_sequence, device_time,
        host_time; in the device's units, times in seconds), each newer than
        the one before, as `for pose in dev` yields them. Shorter than n when
        a replay ends. timeout: seconds to wait for each pose (None: no
        limit); CdmTimeoutError when one does not come."""
        import numpy as np
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ValueError("read: n must be an int >= 0, got %r" % (n,))
        out = np.zeros(n, dtype=pose_dtype())
        after: Optional[int] = None
        for i in range(n):
            pose = self.wait_pose(timeout, after)
            if pose.status == Error.END_OF_STREAM and after is not None and pose.host_sequence <= after:
                return out[:i]
            out[i] = pose_record(pose)
            if pose.is_end_of_stream:
                return out[:i + 1]
            after = pose.host_sequence
        return out


EVENT_NAMES = {1: "disconnected", 2: "reconnected", 3: "stale", 4: "fresh", 5: "end_of_stream"}


def _make_event_callback(fn: Callable[[str, str], Any], state: _CallbackState) -> Any:
    def trampoline(_user: Any, event_p: Any) -> None:
        state.reader = threading.get_ident()
        if state.closed:
            return
        e = event_p.contents
        fn(EVENT_NAMES.get(e.kind, "event %d" % e.kind), _native.text(e.text))
    return _native.cdm_event_fn(trampoline)


def open(uri: Optional[str] = None, stale_timeout_us: int = 0,  # noqa: A001
         on_sample: Optional[Callable[[Sample], Any]] = None, on_event: Optional[Callable[[str, str], Any]] = None,
         calibration: Union[Calibration, str, os.PathLike[str], None] = None, units: str = "mm",
         stale_timeout: Optional[float] = None) -> Device:
    """Opens a master (cdm_open_ex). uri: None or "" ($CDM_DEVICE, else the
    first device), "sim:?...", "replay:FILE", "hid:/dev/hidrawN", "serial:SN".

    on_sample, if given, is called as on_sample(cdm.Sample) on the device's
    reader thread for every report; it must return quickly.
    on_event (since 1.1), if given, is called as on_event(kind, text) on the
    reader thread when the device's state changes; kind is "disconnected",
    "reconnected", "stale", "fresh" or "end_of_stream".
    calibration (since 1.2), if given: a cdm.Calibration or the path of a
    calibration JSON, applied as soon as the device is open
    (set_calibration): the reports the reader took before that (an unpaced
    sim: or replay: gives some) have nominal poses, without
    PoseFlag.COMPENSATED. A
    calibration with a user effect needs it registered in this process
    first (cdm.register_effect, cdm.load_plugin); so does a sim: URI that
    hides one (effects=, truth=).
    units: "mm" (the default: mm, mm/s, quaternions (w, x, y, z), as the C
    API) or "m" (metres, m/s, quaternions (x, y, z, w), as ROS): the units of
    every Pose this device returns (cdm.records).
    stale_timeout: seconds after which a pose is flagged stale (None: the
    library's default, 50 ms); stale_timeout_us is the same in µs."""
    check_units(units, "open")
    if stale_timeout is not None:
        if stale_timeout_us:
            raise ValueError("open: give stale_timeout (s) or stale_timeout_us, not both")
        if not 0 <= stale_timeout < 4294.967296:
            raise ValueError("open: stale_timeout %r s is outside 0..4294 s" % (stale_timeout,))
        stale_timeout_us = int(round(stale_timeout * 1e6))
    L = _native.lib()
    cal: Optional[Calibration] = None
    if calibration is not None:
        from .calibration import Calibration
        cal = calibration if isinstance(calibration, Calibration) else Calibration.load(calibration)
    opts = _native.cdm_open_options()
    if not 0 <= int(stale_timeout_us) < 2**32:
        raise ValueError("open: stale_timeout_us %r is outside 0..2^32-1" % (stale_timeout_us,))
    opts.stale_timeout_us = int(stale_timeout_us)
    callback: Any = None
    state = _CallbackState()
    if on_sample is not None:
        if not callable(on_sample):
            raise TypeError("open: on_sample must be callable, got %r" % (on_sample,))
        callback = _make_sample_callback(on_sample, units, state)
        opts.on_sample = callback
    if on_event is not None:
        if not callable(on_event):
            raise TypeError("open: on_event must be callable, got %r" % (on_event,))
        event_callback = _make_event_callback(on_event, state)
        opts.on_event = event_callback
        callback = (callback, event_callback)  # both kept alive by the Device
    h = ctypes.c_void_p()
    # A C string ends at its first NUL: "sim:\x00rate=5" would open "sim:".
    if uri is not None and not isinstance(uri, str):
        raise TypeError("open: uri must be a str or None, got %s" % type(uri).__name__)
    if uri is not None and "\x00" in uri:
        raise ValueError("open: uri %r contains a NUL character" % (uri,))
    raw_uri = None if uri is None else uri.encode("utf-8")
    rc = L.cdm_open_ex(raw_uri, ctypes.byref(opts), ctypes.byref(h))
    if rc < 0:
        raise _native.fail(rc, "cdm_open")
    if not h.value:
        raise CdmError(Error.CDM_ERR_INTERNAL, "cdm_open returned CDM_OK and no handle", function="cdm_open")
    dev = Device(h, uri, callback, units, state)
    if cal is not None:
        try:
            dev.set_calibration(cal)
        except BaseException:
            dev.close()
            raise
        finally:
            if cal is not calibration:
                cal.close()
    return dev


def enumerate_devices() -> List[DeviceInfo]:
    """Information about every connected master (an empty list is not an error)."""
    L = _native.lib()
    lst = ctypes.c_void_p()
    rc = L.cdm_enumerate(ctypes.byref(lst))
    if rc < 0:
        raise _native.fail(rc, "cdm_enumerate")
    try:
        out: List[DeviceInfo] = []
        for i in range(L.cdm_device_list_count(lst)):
            info = _native.cdm_device_info()
            rc = L.cdm_device_list_get(lst, i, ctypes.byref(info))
            if rc < 0:
                raise _native.fail(rc, "cdm_device_list_get")
            out.append(DeviceInfo._from_c(info))
        return out
    finally:
        L.cdm_device_list_free(lst)
