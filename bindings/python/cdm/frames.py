"""The pose in other conventions: metres and quaternions x, y, z, w, in the
device frame, in ROS's REP 103 frame or in Unity's.

The device frame (docs/protocol.md) is right-handed, in mm: the y-z plane is
the cable plane, x leaves it. Mounted the usual way, upright in front of the
user (the cable plane vertical and facing them), device x points toward the
user, y to the user's right, z up. From there:

    ROS, REP 103 (right-handed, x forward, y left, z up; "forward" is away
    from the user, toward the robot):
        ros = (-device.x, -device.y, device.z)        a half turn about z
    Unity (left-handed, x right, y up, z forward):
        unity = (device.y, device.z, -device.x)       determinant -1

A rotation is carried with the same change of frame, R' = C R C^T; as a
quaternion that keeps the component formula v' = q' v q'^-1 both frames
use. A master mounted another way changes only the matrix C (`frame=`).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence, Tuple

if TYPE_CHECKING:
    from .records import Pose

__all__ = ["ROS_FROM_DEVICE", "UNITY_FROM_DEVICE", "to_frame", "to_ros", "to_unity", "metres_xyzw"]

Matrix = Tuple[Tuple[float, float, float], Tuple[float, float, float], Tuple[float, float, float]]
Vec3 = Tuple[float, float, float]
QuatXYZW = Tuple[float, float, float, float]

ROS_FROM_DEVICE: Matrix = ((-1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0))
UNITY_FROM_DEVICE: Matrix = ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0))


def _det(c: Matrix) -> float:
    return (c[0][0] * (c[1][1] * c[2][2] - c[1][2] * c[2][1]) - c[0][1] * (c[1][0] * c[2][2] - c[1][2] * c[2][0])
            + c[0][2] * (c[1][0] * c[2][1] - c[1][1] * c[2][0]))


def _apply(c: Matrix, v: Sequence[float]) -> Vec3:
    return (c[0][0] * v[0] + c[0][1] * v[1] + c[0][2] * v[2], c[1][0] * v[0] + c[1][1] * v[1] + c[1][2] * v[2],
            c[2][0] * v[0] + c[2][1] * v[1] + c[2][2] * v[2])


def to_frame(position_mm: Sequence[float], orientation_wxyz: Sequence[float], frame: Matrix) -> Tuple[Vec3, QuatXYZW]:
    """(position in metres, quaternion x, y, z, w) in the frame whose axes are
    the rows of `frame` (an orthonormal 3x3 matrix, device -> target)."""
    d = _det(frame)
    if not (abs(abs(d) - 1.0) < 1e-9):
        raise ValueError("frame must be an orthonormal matrix (determinant +-1), got determinant %r" % d)
    w, x, y, z = (float(v) for v in orientation_wxyz)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not n > 0 or not math.isfinite(n):
        raise ValueError("orientation must be a non-zero finite quaternion (w, x, y, z), got %r"
                         % (tuple(orientation_wxyz),))
    # The rotation axis is a pseudovector: under C it maps to det(C) * C axis,
    # while the angle (the scalar part) stays.
    axis = _apply(frame, (x / n, y / n, z / n))
    q = (d * axis[0], d * axis[1], d * axis[2], w / n)
    p = _apply(frame, [float(v) / 1000.0 for v in position_mm])
    return p, q


def _mm_wxyz(pose: Pose) -> Tuple[Vec3, Tuple[float, float, float, float]]:
    """A Pose's position in mm and orientation (w, x, y, z), whatever its units."""
    if getattr(pose, "units", "mm") == "m":  # any object with position and orientation: mm
        x, y, z = pose.position
        qx, qy, qz, qw = pose.orientation
        return (x * 1000.0, y * 1000.0, z * 1000.0), (qw, qx, qy, qz)
    return pose.position, pose.orientation


def _pose_to(pose: Pose, frame: Matrix) -> Tuple[Vec3, QuatXYZW]:
    position_mm, orientation_wxyz = _mm_wxyz(pose)
    return to_frame(position_mm, orientation_wxyz, frame)


def metres_xyzw(pose: Pose) -> Tuple[Vec3, QuatXYZW]:
    """A cdm.Pose (of either units) in the device frame, in metres, quaternion x, y, z, w."""
    return _pose_to(pose, ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))


def to_ros(pose: Pose) -> Tuple[Vec3, QuatXYZW]:
    """A cdm.Pose (of either units) in ROS's REP 103 frame (see the module's note), metres, x, y, z, w."""
    return _pose_to(pose, ROS_FROM_DEVICE)


def to_unity(pose: Pose) -> Tuple[Vec3, QuatXYZW]:
    """A cdm.Pose (of either units) in Unity's frame (left-handed, y up), metres, x, y, z, w."""
    return _pose_to(pose, UNITY_FROM_DEVICE)
