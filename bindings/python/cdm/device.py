"""Devices: open, poses, raw values, information, counters, stored calibration."""
import ctypes
import math
import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional, Tuple

from . import _native
from .constants import Button, Error, PoseFlag
from .errors import CdmError

# Return codes of cdm_get_pose / cdm_wait_pose / cdm_get_raw that come with a
# filled record: the pose is the last one, and its flags say why it is old.
_FILLED = (Error.CDM_ERR_STALE, Error.CDM_ERR_DISCONNECTED, Error.CDM_ERR_END_OF_STREAM)


@dataclass(frozen=True)
class Pose:
    """cdm_pose as Python values. position in mm (device frame: x out of the
    cable plane), orientation a unit quaternion (w, x, y, z), grip in rad.

    status is what the call returned: CDM_OK, or CDM_ERR_STALE /
    CDM_ERR_DISCONNECTED / CDM_ERR_END_OF_STREAM for a pose that is still the
    last one the device gave (see flags)."""
    position: Tuple[float, float, float]
    orientation: Tuple[float, float, float, float]
    grip: float
    buttons: int
    sequence: int
    dropped: int
    flags: int
    device_time_us: int
    host_time_ns: int
    status: int = 0
    host_sequence: int = 0  # since 1.1: poses published by this handle so far; pass to wait_pose(after=)
    # since 1.1: mm/s, device frame; a low-passed difference (50 Hz, ~3.7 ms lag: docs/protocol.md)
    velocity: Tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def _from_c(cls, p, status=0):
        return cls(tuple(p.position), tuple(p.orientation), p.grip, p.buttons, p.sequence, p.dropped,
                   p.flags, p.device_time_us, p.host_time_ns, int(status), int(p.host_sequence),
                   tuple(p.velocity))

    @property
    def is_stale(self):
        return bool(self.flags & PoseFlag.CDM_POSE_STALE)

    @property
    def is_disconnected(self):
        return bool(self.flags & PoseFlag.CDM_POSE_DISCONNECTED)

    @property
    def is_compensated(self):
        return bool(self.flags & PoseFlag.CDM_POSE_COMPENSATED)

    @property
    def is_out_of_workspace(self):
        return bool(self.flags & PoseFlag.CDM_POSE_OUT_OF_WORKSPACE)

    @property
    def is_end_of_stream(self):
        return bool(self.flags & PoseFlag.CDM_POSE_END_OF_STREAM or self.status == Error.CDM_ERR_END_OF_STREAM)

    @property
    def is_fresh(self):
        """A current pose: returned with CDM_OK."""
        return self.status == Error.CDM_OK

    def pressed(self, button):
        """pose.pressed(cdm.CDM_BUTTON_CLUTCH)"""
        return bool(self.buttons & int(button))

    @property
    def clutch(self):
        return self.pressed(Button.CDM_BUTTON_CLUTCH)


@dataclass(frozen=True)
class Raw:
    """cdm_raw: the newest report's sensor values."""
    status: int
    pot_adc: Tuple[int, int, int, int]
    hall_adc: int
    buttons: int
    quat_q14: Tuple[int, int, int, int]
    sequence: int
    lengths_mm: Tuple[float, float, float, float]
    device_time_us: int
    host_time_ns: int
    return_code: int = 0

    @classmethod
    def _from_c(cls, r, code=0):
        return cls(r.status, tuple(r.pot_adc), r.hall_adc, r.buttons, tuple(r.quat_q14), r.sequence,
                   tuple(r.lengths_mm), r.device_time_us, r.host_time_ns, int(code))

    @property
    def quaternion(self):
        """quat_q14 scaled to (w, x, y, z)."""
        return tuple(q / 16384.0 for q in self.quat_q14)


@dataclass(frozen=True)
class DeviceInfo:
    vendor_id: int
    product_id: int
    uri: str
    serial: str
    firmware: str
    transport: str
    protocol_version: int
    adc_bits: int
    pot_scale_mm: Tuple[float, float, float, float]
    pot_offset_mm: Tuple[float, float, float, float]
    a_mm: float
    b_mm: float
    m_mm: float
    report_rate_hz: float
    hall_closed: float
    hall_open: float
    grip_open_rad: float

    @classmethod
    def _from_c(cls, i):
        def s(b):
            return b.decode("utf-8", "replace")
        return cls(i.vendor_id, i.product_id, s(i.uri), s(i.serial), s(i.firmware), s(i.transport),
                   i.protocol_version, i.adc_bits, tuple(i.pot_scale_mm), tuple(i.pot_offset_mm), i.a_mm,
                   i.b_mm, i.m_mm, i.report_rate_hz, i.hall_closed, i.hall_open, i.grip_open_rad)


@dataclass(frozen=True)
class Stats:
    reports: int
    malformed: int
    dropped: int
    out_of_workspace: int
    reconnects: int
    sequence_jumps: int = 0  # since 1.1: counter resets or corruptions (not in dropped)
    out_of_order: int = 0  # since 1.1: duplicated or late reports, discarded
    replay_truncated_bytes: int = 0  # since 1.1: incomplete tail a replay dropped


@dataclass(frozen=True)
class Sample:
    """What an on_sample callback receives: one report as it arrived."""
    report: bytes
    raw: Raw
    pose: Pose
    #: since 1.1: ns when the report was first received (a replay: the time
    #: recorded with it; otherwise raw.host_time_ns)
    source_time_ns: int = 0


class _CallbackState:
    """Shared by a device and its callbacks: which thread is the reader (the
    one the callbacks run on), and whether close() began (no user callback
    runs after it)."""

    def __init__(self):
        self.reader = None
        self.closed = False


def _make_sample_callback(fn, state):
    def trampoline(_user, sample_p):
        state.reader = threading.get_ident()
        if state.closed:
            return
        s = sample_p.contents
        report = ctypes.string_at(s.report, s.report_len) if s.report else b""
        raw = Raw._from_c(s.raw.contents) if s.raw else None
        pose = Pose._from_c(s.pose.contents) if s.pose else None
        fn(Sample(report, raw, pose, s.source_time_ns))
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

    def __init__(self, handle, uri, callback=None, state=None):
        self._h = handle
        self.uri = uri
        # The ctypes callback object must outlive the native handle: the reader
        # thread calls it until cdm_close returns.
        self._callback = callback
        self._state = state or _CallbackState()
        self._lock = threading.Condition(threading.Lock())
        self._calls = 0  # native calls in progress on self._h

    # -- lifetime
    def close(self):
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

    def _finish_close(self, h):
        with self._lock:
            while self._calls:
                self._lock.wait()
            self._h = None
        _native.lib().cdm_close(h)
        self._callback = None

    @property
    def closed(self):
        return self._h is None or self._state.closed

    def __repr__(self):
        return "<cdm.Device %r%s>" % (self.uri, " closed" if self.closed else "")

    def _handle(self, function):
        """The native handle, uncounted: for a caller that keeps the device
        open during its own native call (the package's calls use _enter)."""
        if self._h is None or self._state.closed:
            raise CdmError(Error.CDM_ERR_INVALID_ARG, "device %r is closed" % (self.uri,), function=function)
        return self._h

    def _enter(self, function):
        """The handle, counted as in use until _leave(): close() waits for it."""
        with self._lock:
            if self._h is None or self._state.closed:
                raise CdmError(Error.CDM_ERR_INVALID_ARG, "device %r is closed" % (self.uri,), function=function)
            self._calls += 1
            return self._h

    def _leave(self):
        with self._lock:
            self._calls -= 1
            if self._calls == 0:
                self._lock.notify_all()

    def _fail(self, code, function):
        L = _native.lib()
        detail = (L.cdm_thread_error() or b"").decode("utf-8", "replace")
        if not detail and not self.closed:
            detail = self.error_detail()
        return _native.fail(code, function, detail)

    # -- poses
    def get_pose(self):
        """The newest pose, without blocking.

        Raises CdmError(CDM_ERR_NO_DATA) before the first report (use
        wait_pose first). A stale, disconnected or ended stream is *not* an
        exception: the last pose is returned with its flags and .status set, as
        a control loop wants to hold the last command and look at the flags."""
        h = self._enter("cdm_get_pose")
        try:
            p = _native.cdm_pose()
            rc = _native.lib().cdm_get_pose(h, ctypes.byref(p))
            if rc < 0 and rc not in _FILLED:
                raise self._fail(rc, "cdm_get_pose")
            return Pose._from_c(p, rc)
        finally:
            self._leave()

    # The C call waits in slices this long, so that Ctrl-C (handled by Python
    # between two foreign calls) interrupts a long wait within 0.1 s.
    _WAIT_SLICE_MS = 100

    def wait_pose(self, timeout=1.0, after=None):
        """Blocks until a pose newer than `after` (a Pose.host_sequence; None:
        the newest pose at the time of the call) exists; returns at once if one
        already does, so a loop passing the last pose's host_sequence never
        misses one. timeout in seconds (None: no limit). Raises
        CdmError(CDM_ERR_TIMEOUT) when none came in time; otherwise returns
        like get_pose. Ctrl-C interrupts it."""
        h = self._enter("cdm_wait_pose_after")
        try:
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
            return Pose._from_c(p, rc)
        finally:
            self._leave()

    def get_raw(self):
        """Raw values of the newest report (same returns as get_pose)."""
        h = self._enter("cdm_get_raw")
        try:
            r = _native.cdm_raw()
            rc = _native.lib().cdm_get_raw(h, ctypes.byref(r))
            if rc < 0 and rc not in _FILLED:
                raise self._fail(rc, "cdm_get_raw")
            return Raw._from_c(r, rc)
        finally:
            self._leave()

    # -- information
    def info(self):
        h = self._enter("cdm_get_info")
        try:
            i = _native.cdm_device_info()
            rc = _native.lib().cdm_get_info(h, ctypes.byref(i))
            if rc < 0:
                raise self._fail(rc, "cdm_get_info")
            return DeviceInfo._from_c(i)
        finally:
            self._leave()

    def stats(self):
        h = self._enter("cdm_get_stats")
        try:
            s = _native.cdm_stats()
            rc = _native.lib().cdm_get_stats(h, ctypes.byref(s))
            if rc < 0:
                raise self._fail(rc, "cdm_get_stats")
            return Stats(s.reports, s.malformed, s.dropped, s.out_of_workspace, s.reconnects, s.sequence_jumps,
                         s.out_of_order, s.replay_truncated_bytes)
        finally:
            self._leave()

    def error_detail(self):
        """The handle's last asynchronous problem (cdm_device_error), "" if none."""
        h = self._enter("cdm_device_error")
        try:
            buf = ctypes.create_string_buffer(1024)
            rc = _native.lib().cdm_device_error(h, buf, len(buf))
            if rc < 0:
                return ""
            return buf.value.decode("utf-8", "replace")
        finally:
            self._leave()

    def set_stale_timeout(self, seconds):
        """Poses older than this are flagged stale; 0 restores the default (50 ms)."""
        us = int(round(seconds * 1e6))
        if not 0 <= us < 2**32:
            raise ValueError("set_stale_timeout: %r s is outside 0..4294 s" % (seconds,))
        h = self._enter("cdm_set_stale_timeout")
        try:
            rc = _native.lib().cdm_set_stale_timeout(h, us)
            if rc < 0:
                raise self._fail(rc, "cdm_set_stale_timeout")
        finally:
            self._leave()

    # -- calibration
    def set_calibration(self, calibration):
        """Applies a cdm.Calibration to the poses from the next report on (the
        library copies it); None returns to the nominal model."""
        h = self._enter("cdm_set_calibration")
        try:
            ch = None if calibration is None else calibration._handle("cdm_set_calibration")
            rc = _native.lib().cdm_set_calibration(h, ch)
            if rc < 0:
                raise self._fail(rc, "cdm_set_calibration")
        finally:
            self._leave()

    def read_stored_calibration(self):
        """The calibration bytes stored in the device (CdmError CDM_ERR_CRC when corrupt)."""
        h = self._enter("cdm_device_calibration_read")
        try:
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
        finally:
            self._leave()

    def write_stored_calibration(self, data):
        """Stores bytes (typically a calibration JSON) in the device."""
        if isinstance(data, str):
            data = data.encode("utf-8")
        data = bytes(data)
        h = self._enter("cdm_device_calibration_write")
        try:
            rc = _native.lib().cdm_device_calibration_write(h, data, len(data))
            if rc < 0:
                raise self._fail(rc, "cdm_device_calibration_write")
        finally:
            self._leave()


EVENT_NAMES = {1: "disconnected", 2: "reconnected", 3: "stale", 4: "fresh", 5: "end_of_stream"}


def _make_event_callback(fn, state):
    def trampoline(_user, event_p):
        state.reader = threading.get_ident()
        if state.closed:
            return
        e = event_p.contents
        fn(EVENT_NAMES.get(e.kind, "event %d" % e.kind), (e.text or b"").decode("utf-8", "replace"))
    return _native.cdm_event_fn(trampoline)


def open(uri=None, stale_timeout_us=0, on_sample=None, on_event=None, calibration=None):  # noqa: A001
    """Opens a master (cdm_open_ex). uri: None or "" ($CDM_DEVICE, else the
    first device), "sim:?...", "replay:FILE", "hid:/dev/hidrawN", "serial:SN".

    on_sample, if given, is called as on_sample(cdm.Sample) on the device's
    reader thread for every report; it must return quickly.
    on_event (since 1.1), if given, is called as on_event(kind, text) on the
    reader thread when the device's state changes; kind is "disconnected",
    "reconnected", "stale", "fresh" or "end_of_stream".
    calibration (since 1.2), if given: a cdm.Calibration or the path of a
    calibration JSON, applied from the first pose on (set_calibration). A
    calibration with a user effect needs it registered in this process
    first (cdm.register_effect, cdm.load_plugin); so does a sim: URI that
    hides one (effects=, truth=)."""
    L = _native.lib()
    cal = None
    if calibration is not None:
        from .calibration import Calibration
        cal = calibration if isinstance(calibration, Calibration) else Calibration.load(calibration)
    opts = _native.cdm_open_options()
    if not 0 <= int(stale_timeout_us) < 2**32:
        raise ValueError("open: stale_timeout_us %r is outside 0..2^32-1" % (stale_timeout_us,))
    opts.stale_timeout_us = int(stale_timeout_us)
    callback = None
    state = _CallbackState()
    if on_sample is not None:
        if not callable(on_sample):
            raise TypeError("open: on_sample must be callable, got %r" % (on_sample,))
        callback = _make_sample_callback(on_sample, state)
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
    dev = Device(h, uri, callback, state)
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


def enumerate_devices():
    """Information about every connected master (an empty list is not an error)."""
    L = _native.lib()
    lst = ctypes.c_void_p()
    rc = L.cdm_enumerate(ctypes.byref(lst))
    if rc < 0:
        raise _native.fail(rc, "cdm_enumerate")
    try:
        out = []
        for i in range(L.cdm_device_list_count(lst)):
            info = _native.cdm_device_info()
            rc = L.cdm_device_list_get(lst, i, ctypes.byref(info))
            if rc < 0:
                raise _native.fail(rc, "cdm_device_list_get")
            out.append(DeviceInfo._from_c(info))
        return out
    finally:
        L.cdm_device_list_free(lst)
