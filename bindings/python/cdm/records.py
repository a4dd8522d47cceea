"""What a device returns: poses, raw values, information, counters, samples.

Units: a Pose is in the units its device was opened with, cdm.open(...,
units=...). "mm" (the default, the C API's): position in mm, velocity in
mm/s, orientation a unit quaternion (w, x, y, z). "m" (ROS's, REP 103 units):
position in metres, velocity in m/s, orientation (x, y, z, w). Both are in
the device frame; cdm.frames turns a pose into ROS's or Unity's axes. Times
are in seconds (device_time, host_time); the integer fields they come from
(device_time_us, host_time_ns) stay, exact.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Optional, Tuple

from .constants import Button, Error, PoseFlag

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

__all__ = ["Pose", "Raw", "DeviceInfo", "Stats", "Sample", "UNITS", "pose_dtype"]

Vec3 = Tuple[float, float, float]
Vec4 = Tuple[float, float, float, float]

#: The values of cdm.open(units=...): mm and (w, x, y, z) as the C API, or
#: metres and (x, y, z, w) as ROS.
UNITS = ("mm", "m")


def check_units(units: str, function: str) -> str:
    """units itself, or ValueError naming the function and the choices."""
    if units not in UNITS:
        raise ValueError("%s: units must be one of %s, got %r" % (function, ", ".join(map(repr, UNITS)), units))
    return units


def _flags(value: int) -> PoseFlag:
    return PoseFlag(int(value))


def _status(code: int) -> int:
    try:
        return Error(int(code))
    except ValueError:
        return int(code)


@dataclass(frozen=True)
class Pose:
    """One pose of the master (cdm_pose), in the device frame (x out of the
    cable plane), in the units the device was opened with (`units`: "mm",
    the default, or "m"; see the module's note).

    position     (x, y, z): mm, or m with units="m"
    orientation  unit quaternion: (w, x, y, z), or (x, y, z, w) with units="m"
    grip         gripper opening, rad
    buttons      cdm.Button bits (pose.pressed(cdm.Button.CLUTCH))
    flags        cdm.PoseFlag bits (stale, disconnected, compensated, ...)
    status       what the call returned: Error.OK, or Error.STALE /
                 DISCONNECTED / END_OF_STREAM for a pose that is still the
                 last one the device gave (see flags)
    host_sequence  poses published by this handle so far (wait_pose(after=))
    velocity     low-passed difference (50 Hz, ~3.7 ms lag: docs/protocol.md),
                 mm/s or m/s
    device_time, host_time  seconds (the _us and _ns fields, converted)
    """
    position: Vec3
    orientation: Vec4
    grip: float
    buttons: Button
    sequence: int
    dropped: int
    flags: PoseFlag
    device_time_us: int
    host_time_ns: int
    status: int = 0
    host_sequence: int = 0
    velocity: Vec3 = (0.0, 0.0, 0.0)
    units: str = "mm"

    @classmethod
    def _from_c(cls, p: Any, status: int = 0, units: str = "mm") -> Pose:
        x, y, z = (float(v) for v in p.position)
        w, qx, qy, qz = (float(v) for v in p.orientation)
        vx, vy, vz = (float(v) for v in p.velocity)
        position: Vec3 = (x, y, z)
        orientation: Vec4 = (w, qx, qy, qz)
        velocity: Vec3 = (vx, vy, vz)
        if units == "m":
            position, velocity = (x / 1000.0, y / 1000.0, z / 1000.0), (vx / 1000.0, vy / 1000.0, vz / 1000.0)
            orientation = (qx, qy, qz, w)
        return cls(position, orientation, float(p.grip), Button(int(p.buttons)), int(p.sequence), int(p.dropped),
                   _flags(p.flags), int(p.device_time_us), int(p.host_time_ns), _status(status),
                   int(p.host_sequence), velocity, units)

    @property
    def device_time(self) -> float:
        """The device's clock at the report, seconds."""
        return self.device_time_us * 1e-6

    @property
    def host_time(self) -> float:
        """The host's monotonic clock when the report arrived, seconds."""
        return self.host_time_ns * 1e-9

    @property
    def position_array(self) -> npt.NDArray[np.float64]:
        """position as a numpy array, shape (3,) (needs numpy)."""
        import numpy as np
        return np.array(self.position, dtype=np.float64)

    @property
    def orientation_array(self) -> npt.NDArray[np.float64]:
        """orientation as a numpy array, shape (4,), in the pose's order (needs numpy)."""
        import numpy as np
        return np.array(self.orientation, dtype=np.float64)

    @property
    def velocity_array(self) -> npt.NDArray[np.float64]:
        """velocity as a numpy array, shape (3,) (needs numpy)."""
        import numpy as np
        return np.array(self.velocity, dtype=np.float64)

    @property
    def is_stale(self) -> bool:
        """The pose is older than the stale timeout."""
        return bool(self.flags & PoseFlag.STALE)

    @property
    def is_disconnected(self) -> bool:
        """The device is gone; this is the last pose it gave."""
        return bool(self.flags & PoseFlag.DISCONNECTED)

    @property
    def is_compensated(self) -> bool:
        """A calibration corrected this pose."""
        return bool(self.flags & PoseFlag.COMPENSATED)

    @property
    def is_out_of_workspace(self) -> bool:
        """The readings put the holder outside the workspace."""
        return bool(self.flags & PoseFlag.OUT_OF_WORKSPACE)

    @property
    def is_end_of_stream(self) -> bool:
        """A replay reached its end; this is its last pose."""
        return bool(self.flags & PoseFlag.END_OF_STREAM or self.status == Error.END_OF_STREAM)

    @property
    def is_fresh(self) -> bool:
        """A current pose: returned with Error.OK."""
        return self.status == Error.OK

    def pressed(self, button: int) -> bool:
        """Whether `button` (cdm.Button.CLUTCH, ...) is held."""
        return bool(self.buttons & int(button))

    @property
    def clutch(self) -> bool:
        """The clutch button is held."""
        return self.pressed(Button.CLUTCH)


def pose_dtype() -> np.dtype[np.void]:
    """The numpy structured dtype of Device.read(): one record per pose, the
    fields of Pose (times in seconds, device_time and host_time)."""
    import numpy as np
    return np.dtype([("position", np.float64, (3,)), ("orientation", np.float64, (4,)),
                     ("velocity", np.float64, (3,)), ("grip", np.float64), ("buttons", np.uint32),
                     ("flags", np.uint32), ("sequence", np.uint32), ("dropped", np.uint32), ("status", np.int32),
                     ("host_sequence", np.uint64), ("device_time", np.float64), ("host_time", np.float64)])


def pose_record(pose: Pose) -> Tuple[Any, ...]:
    """A Pose as one record of pose_dtype()."""
    return (pose.position, pose.orientation, pose.velocity, pose.grip, int(pose.buttons), int(pose.flags),
            pose.sequence, pose.dropped, int(pose.status), pose.host_sequence, pose.device_time, pose.host_time)


@dataclass(frozen=True)
class Raw:
    """The newest report's sensor values (cdm_raw); return_code is what the call returned."""
    status: int
    pot_adc: Tuple[int, int, int, int]
    hall_adc: int
    buttons: Button
    quat_q14: Tuple[int, int, int, int]
    sequence: int
    lengths_mm: Vec4
    device_time_us: int
    host_time_ns: int
    return_code: int = 0

    @classmethod
    def _from_c(cls, r: Any, code: int = 0) -> Raw:
        a, b, c, d = (int(v) for v in r.pot_adc)
        qw, qx, qy, qz = (int(v) for v in r.quat_q14)
        la, lb, lc, ld = (float(v) for v in r.lengths_mm)
        return cls(int(r.status), (a, b, c, d), int(r.hall_adc), Button(int(r.buttons)), (qw, qx, qy, qz),
                   int(r.sequence), (la, lb, lc, ld), int(r.device_time_us), int(r.host_time_ns), _status(code))

    @property
    def quaternion(self) -> Vec4:
        """quat_q14 scaled to (w, x, y, z)."""
        w, x, y, z = (q / 16384.0 for q in self.quat_q14)
        return (w, x, y, z)

    @property
    def device_time(self) -> float:
        """The device's clock at the report, seconds."""
        return self.device_time_us * 1e-6

    @property
    def host_time(self) -> float:
        """The host's monotonic clock when the report arrived, seconds."""
        return self.host_time_ns * 1e-9


@dataclass(frozen=True)
class DeviceInfo:
    """What a device says about itself (cdm_device_info); lengths in mm, angles in rad."""
    vendor_id: int
    product_id: int
    uri: str
    serial: str
    firmware: str
    transport: str
    protocol_version: int
    adc_bits: int
    pot_scale_mm: Vec4
    pot_offset_mm: Vec4
    a_mm: float
    b_mm: float
    m_mm: float
    report_rate_hz: float
    hall_closed: float
    hall_open: float
    grip_open_rad: float

    @classmethod
    def _from_c(cls, i: Any) -> DeviceInfo:
        def s(b: bytes) -> str:
            return b.decode("utf-8", "replace")

        def v4(a: Any) -> Vec4:
            w, x, y, z = (float(v) for v in a)
            return (w, x, y, z)
        return cls(int(i.vendor_id), int(i.product_id), s(i.uri), s(i.serial), s(i.firmware), s(i.transport),
                   int(i.protocol_version), int(i.adc_bits), v4(i.pot_scale_mm), v4(i.pot_offset_mm),
                   float(i.a_mm), float(i.b_mm), float(i.m_mm), float(i.report_rate_hz), float(i.hall_closed),
                   float(i.hall_open), float(i.grip_open_rad))


@dataclass(frozen=True)
class Stats:
    """A device's counters since it was opened (cdm_stats)."""
    reports: int
    malformed: int
    dropped: int
    out_of_workspace: int
    reconnects: int
    sequence_jumps: int = 0  # counter resets or corruptions (not in dropped)
    out_of_order: int = 0  # duplicated or late reports, discarded
    replay_truncated_bytes: int = 0  # incomplete tail a replay dropped
    restarts: int = 0  # the device restarted its counter (a firmware restart; not in sequence_jumps)


@dataclass(frozen=True)
class Sample:
    """What an on_sample callback receives: one report as it arrived (the
    pose in the device's units)."""
    report: bytes
    raw: Optional[Raw]
    pose: Optional[Pose]
    #: ns when the report was first received (a replay: the time recorded
    #: with it; otherwise raw.host_time_ns)
    source_time_ns: int = 0

    @property
    def source_time(self) -> float:
        """source_time_ns in seconds."""
        return self.source_time_ns * 1e-9


def sample_from_c(s: Any, units: str = "mm") -> Sample:
    """A Sample from the cdm_sample the reader thread hands over."""
    report = ctypes.string_at(s.report, s.report_len) if s.report else b""
    raw = Raw._from_c(s.raw.contents) if s.raw else None
    pose = Pose._from_c(s.pose.contents, 0, units) if s.pose else None
    return Sample(report, raw, pose, int(s.source_time_ns))
