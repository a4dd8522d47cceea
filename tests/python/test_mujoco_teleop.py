"""The teleop mapping of examples/python/mujoco_teleop.py: scaling, frames, clutch."""
import os
import sys

import numpy as np
import pytest

pytest.importorskip("mujoco")
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "examples", "python"))
import mujoco_teleop as mt  # noqa: E402

LEVEL = (1.0, 0.0, 0.0, 0.0)


def test_scaled_motion_in_the_world_frame():
    m = mt.TeleopMapper([0.5, 0.0, 0.3], [1, 0, 0, 0], scale=0.5)
    m.update([50, 0, 0], LEVEL, False)  # anchors
    # 10 mm toward the operator (device +x) is 5 mm toward the operator in the
    # world (world -x); device z up stays up.
    p, _ = m.update([60, 0, 0], LEVEL, False)
    assert p == pytest.approx([0.495, 0.0, 0.3], abs=1e-12)
    p, _ = m.update([60, 0, 20], LEVEL, False)
    assert p == pytest.approx([0.495, 0.0, 0.31], abs=1e-12)


def test_clutch_holds_the_tool_and_re_anchors_without_a_jump():
    m = mt.TeleopMapper([0.5, 0.0, 0.3], [1, 0, 0, 0], scale=1.0)
    m.update([50, 0, 0], LEVEL, False)
    p1, _ = m.update([50, 10, 0], LEVEL, False)
    # Clutch held: the hand travels 40 mm, the tool stays.
    for y in range(10, 50, 5):
        p, _ = m.update([50, y, 0], LEVEL, True)
        assert p == pytest.approx(p1)
    # Released where the hand now is: no jump, then motion resumes from there.
    p, _ = m.update([50, 45, 0], LEVEL, False)
    assert p == pytest.approx(p1)
    p, _ = m.update([50, 55, 0], LEVEL, False)
    assert p == pytest.approx(p1 + np.array([0, -0.010, 0]))  # device +y is world -y


def test_orientation_follows_the_imu_relative_to_the_anchor():
    tool0 = np.array([np.cos(0.2), 0, np.sin(0.2), 0])  # tool starts pitched
    m = mt.TeleopMapper([0.5, 0.0, 0.3], tool0, scale=0.5)
    m.update([50, 0, 0], LEVEL, False)
    a = 0.3  # the grip yaws 0.3 rad about the (shared) vertical axis
    _, q = m.update([50, 0, 0], (np.cos(a / 2), 0, 0, np.sin(a / 2)), False)
    # Orientation is not scaled: the tool turns by the same 0.3 rad about world z.
    expect = mt.qmul(np.array([np.cos(a / 2), 0, 0, np.sin(a / 2)]), tool0)
    assert q == pytest.approx(expect, abs=1e-12)
