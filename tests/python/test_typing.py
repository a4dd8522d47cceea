"""The package's typed, documented surface: docstrings on every public name,
explicit exports, Python-style enums, seconds, metres and numpy views."""
import enum
import inspect
import math

import pytest

import cdm
import cdm.records


def _own_members(cls):
    """Public attributes cls itself defines (not inherited from builtins or enum)."""
    for name, value in vars(cls).items():
        if name.startswith("_") or isinstance(cls, enum.EnumMeta) and name in cls.__members__:
            continue
        yield name, value


def test_every_public_name_has_a_docstring():
    missing = []
    for name in cdm.__all__:
        obj = getattr(cdm, name)
        if isinstance(obj, (int, float, str, tuple)):
            continue  # constants: documented with their enum
        if not (inspect.getdoc(obj) or "").strip():
            missing.append(name)
        if inspect.isclass(obj):
            for mname, m in _own_members(obj):
                target = m.fget if isinstance(m, property) else m
                if callable(target) or isinstance(m, property):
                    if not (getattr(target, "__doc__", None) or "").strip():
                        missing.append("%s.%s" % (name, mname))
    assert not missing, "no docstring: " + ", ".join(missing)


def test_all_is_static_and_complete():
    # mypy reads __all__ to know what `import cdm` exports: every name in it exists.
    for name in cdm.__all__:
        assert hasattr(cdm, name), name
    assert "open" in cdm.__all__ and "Button" in cdm.__all__ and "CDM_BUTTON_CLUTCH" in cdm.__all__


def test_py_typed_marker_is_in_the_package():
    import os
    assert os.path.isfile(os.path.join(os.path.dirname(cdm.__file__), "py.typed"))


@pytest.mark.parametrize("enum_cls, prefix", [
    (cdm.Error, "CDM_ERR_"), (cdm.PoseFlag, "CDM_POSE_"), (cdm.Button, "CDM_BUTTON_"),
    (cdm.EventKind, "CDM_EVENT_"), (cdm.LogLevel, "CDM_LOG_"), (cdm.WatchKind, "CDM_WATCH_"),
    (cdm.WatchFlag, "CDM_WATCH_"), (cdm.EffectStage, "CDM_EFFECT_STAGE_")])
def test_enum_members_drop_the_c_prefix_and_keep_the_c_names(enum_cls, prefix):
    for member in enum_cls:
        assert not member.name.startswith("CDM_"), member
        c_name = "CDM_OK" if member.name == "OK" else prefix + member.name
        assert enum_cls[c_name] is member, c_name  # the C name is an alias of the member
        assert getattr(cdm, c_name) == int(member)  # and the flat constant its value


def test_flags_are_int_flags():
    assert issubclass(cdm.Button, enum.IntFlag) and issubclass(cdm.PoseFlag, enum.IntFlag)
    both = cdm.Button.CLUTCH | cdm.Button.MARK
    assert isinstance(both, cdm.Button) and int(both) == 5 and cdm.Button.CLUTCH in both


def test_error_names_stay_the_c_names():
    err = cdm.CdmError(cdm.Error.TIMEOUT, "x")
    assert err.name == "CDM_ERR_TIMEOUT" and "(CDM_ERR_TIMEOUT)" in str(err)


def test_pose_fields_are_typed_flags_and_seconds():
    with cdm.open("sim:") as dev:
        pose = dev.wait_pose(2.0, after=0)
    assert isinstance(pose.buttons, cdm.Button) and isinstance(pose.flags, cdm.PoseFlag)
    assert pose.status == cdm.Error.OK and isinstance(pose.status, cdm.Error)
    assert pose.device_time == pose.device_time_us * 1e-6
    assert pose.host_time == pose.host_time_ns * 1e-9


def _c_pose():
    p = cdm._native.cdm_pose()
    p.position[:] = (12.5, -40.25, 180.0)
    p.orientation[:] = (0.5, 0.5, -0.5, 0.5)
    p.velocity[:] = (1.0, -2.0, 250.0)
    p.grip, p.buttons, p.flags, p.host_sequence = 0.25, 1, 4, 7
    p.device_time_us, p.host_time_ns = 1500000, 2500000000
    return p


def test_units_m_is_metres_and_ros_quaternion_order():
    # One C pose in both units: a division by 1000 and a reordering, nothing else.
    mm = cdm.records.Pose._from_c(_c_pose(), 0, "mm")
    m = cdm.records.Pose._from_c(_c_pose(), 0, "m")
    assert mm.position == (12.5, -40.25, 180.0) and mm.orientation == (0.5, 0.5, -0.5, 0.5)
    assert m.position == (12.5 / 1000.0, -40.25 / 1000.0, 180.0 / 1000.0)
    assert m.velocity == (1.0 / 1000.0, -2.0 / 1000.0, 250.0 / 1000.0)
    assert m.orientation == (0.5, -0.5, 0.5, 0.5)  # (x, y, z, w)
    assert (m.grip, m.buttons, m.flags, m.device_time, m.host_time) == (mm.grip, mm.buttons, mm.flags, 1.5, 2.5)
    # cdm.frames reads either: the same ROS pose (metres both ways: equal to rounding).
    for a, b in zip(cdm.frames.to_ros(m), cdm.frames.to_ros(mm)):
        assert a == pytest.approx(b, rel=1e-15, abs=1e-18)


def test_a_device_opened_in_metres_returns_metres():
    with cdm.open("sim:", units="m") as dev:
        assert dev.units == "m"
        pose = dev.wait_pose(2.0, after=0)
    assert pose.units == "m"
    # sim:'s workspace is a few hundred mm: in metres every coordinate is under 1.
    assert all(abs(v) < 1.0 for v in pose.position) and any(v != 0.0 for v in pose.position)
    assert math.isclose(sum(q * q for q in pose.orientation), 1.0, rel_tol=1e-9)


def test_units_are_checked():
    with pytest.raises(ValueError, match="units must be one of 'mm', 'm', got 'cm'"):
        cdm.open("sim:", units="cm")


def test_numpy_views_of_a_pose():
    np = pytest.importorskip("numpy")
    with cdm.open("sim:") as dev:
        pose = dev.wait_pose(2.0, after=0)
    assert pose.position_array.shape == (3,) and pose.orientation_array.shape == (4,)
    assert pose.position_array.dtype == np.float64
    assert tuple(pose.position_array) == pose.position and tuple(pose.orientation_array) == pose.orientation


def test_read_returns_a_structured_array_of_successive_poses():
    np = pytest.importorskip("numpy")
    with cdm.open("sim:", units="m") as dev:
        batch = dev.read(20, timeout=2.0)
    assert batch.dtype == cdm.records.pose_dtype() and batch.shape == (20,)
    assert batch["position"].shape == (20, 3) and batch["orientation"].shape == (20, 4)
    assert np.all(np.diff(batch["host_sequence"].astype(np.int64)) >= 1), "each pose newer than the one before"
    assert np.all(np.diff(batch["host_time"]) >= 0)
    assert np.all(np.abs(batch["position"]) < 1.0), "units='m' reaches the batch"
    assert np.allclose(np.sum(batch["orientation"] ** 2, axis=1), 1.0, rtol=1e-9)


def test_read_rejects_a_bad_count():
    with cdm.open("sim:") as dev:
        with pytest.raises(ValueError, match="read: n must be an int >= 0"):
            dev.read(-1)


def test_iterating_a_device_yields_newer_poses_until_closed():
    with cdm.open("sim:") as dev:
        seen = []
        for pose in dev:
            seen.append(pose.host_sequence)
            if len(seen) == 5:
                dev.close()  # on the iterating thread, between two waits
        assert len(seen) == 5 and seen == sorted(set(seen))


def test_iterating_a_replay_ends_at_its_end(tmp_path):
    import os
    import subprocess
    cli = os.environ.get("CDM_CLI")
    if not cli:
        pytest.skip("CDM_CLI is not set (ctest sets it)")
    rec = tmp_path / "r.cdmrec"
    subprocess.run([cli, "record", "sim:", str(rec), "--seconds", "0.3"], check=True, capture_output=True)
    with cdm.open("replay:%s" % rec) as dev:
        poses = list(dev)  # ends by itself
    assert poses, "a 0.3 s recording has poses"
    seqs = [p.host_sequence for p in poses]
    assert seqs == sorted(set(seqs))
    assert poses[-1].is_end_of_stream or poses[-1].status == cdm.Error.OK


def test_stale_timeout_in_seconds():
    with pytest.raises(ValueError, match="not both"):
        cdm.open("sim:", stale_timeout=0.1, stale_timeout_us=100000)
    with cdm.open("sim:", stale_timeout=0.2) as dev:
        dev.wait_pose(2.0, after=0)
