"""cdm.frames: a vector rotated in the device frame and then carried into the
ROS or Unity frame equals the carried vector rotated by the carried
quaternion, with the component formula both engines apply (v' = q v q^-1).
Exact up to rounding (1e-12)."""
import math
import random

import pytest

from cdm import frames


def qrot(q_xyzw, v):
    x, y, z, w = q_xyzw
    # v' = v + 2w (u x v) + 2 u x (u x v), u = (x, y, z)
    u = (x, y, z)
    c1 = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
    c2 = (u[1] * c1[2] - u[2] * c1[1], u[2] * c1[0] - u[0] * c1[2], u[0] * c1[1] - u[1] * c1[0])
    return tuple(v[i] + 2 * w * c1[i] + 2 * c2[i] for i in range(3))


@pytest.mark.parametrize("frame", [frames.ROS_FROM_DEVICE, frames.UNITY_FROM_DEVICE])
def test_rotation_carried_with_the_frame(frame):
    rng = random.Random(7)
    for _ in range(200):
        q = [rng.gauss(0, 1) for _ in range(4)]
        n = math.sqrt(sum(c * c for c in q))
        q_wxyz = [c / n for c in q]
        v = [rng.uniform(-100, 100) for _ in range(3)]
        p, q2 = frames.to_frame(v, q_wxyz, frame)
        dev_xyzw = (q_wxyz[1], q_wxyz[2], q_wxyz[3], q_wxyz[0])
        rotated_then_carried = frames._apply(frame, qrot(dev_xyzw, v))
        carried_then_rotated = qrot(q2, [c * 1000.0 for c in p])
        for a, b in zip(rotated_then_carried, carried_then_rotated):
            assert a == pytest.approx(b, abs=1e-9)
        assert sum(c * c for c in q2) == pytest.approx(1.0, abs=1e-12)


def test_axes_as_documented():
    class P:
        position = (100.0, 20.0, 30.0)
        orientation = (1.0, 0.0, 0.0, 0.0)
    assert frames.to_ros(P)[0] == pytest.approx((-0.1, -0.02, 0.03))
    assert frames.to_unity(P)[0] == pytest.approx((0.02, 0.03, -0.1))
    assert frames.metres_xyzw(P) == (pytest.approx((0.1, 0.02, 0.03)), (0.0, 0.0, 0.0, 1.0))
    with pytest.raises(ValueError):
        frames.to_frame((0, 0, 0), (0, 0, 0, 0), frames.ROS_FROM_DEVICE)
    with pytest.raises(ValueError):
        frames.to_frame((0, 0, 0), (1, 0, 0, 0), ((2, 0, 0), (0, 1, 0), (0, 0, 1)))
