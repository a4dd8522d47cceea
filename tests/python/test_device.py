"""The simulated master through the Python binding."""
import gc
import math
import statistics
import threading
import time

import pytest

import cdm

STILL = "sim:?motion=still&noise=0&imu_noise=0&hall_noise=0"


def test_still_pose_is_where_the_simulation_holds_it():
    with cdm.open(STILL) as dev:
        p = dev.wait_pose(2.0)
        info = dev.info()
        raw = dev.get_raw()
    assert p.status == cdm.CDM_OK and p.is_fresh and not p.is_stale
    # motion=still: holder at (50, 0, 0) mm. With noise off, the only error is
    # the pots' quantisation, +-scale/2 per cable; a common length error dl
    # moves the holder by dl * L / x out of the plane (the worst direction),
    # L the cable length.
    L = max(raw.lengths_mm)
    tol = 0.5 * max(info.pot_scale_mm) * L / 50.0 * 1.01
    assert abs(p.position[0] - 50.0) <= tol and abs(p.position[1]) <= tol and abs(p.position[2]) <= tol, \
        (p.position, tol)
    # A level grip, quantised to q14: each component within half a count.
    assert p.orientation == pytest.approx((1.0, 0.0, 0.0, 0.0), abs=0.5 / 16384 + 1e-12)
    # Jaw closed, Hall quantised to one count of (hall_closed - hall_open) over grip_open_rad.
    assert 0.0 <= p.grip <= info.grip_open_rad / abs(info.hall_closed - info.hall_open) + 1e-12
    assert p.buttons == 0 and not p.clutch
    assert info.transport == "sim" and info.vendor_id == 0x1209 and info.product_id == 0xCD01
    assert len(info.pot_scale_mm) == 4 and info.report_rate_hz > 0
    assert raw.quaternion == pytest.approx((1, 0, 0, 0), abs=1e-4)


def test_poses_stream_in_order_with_the_noise_the_simulation_adds():
    noise = 0.05
    with cdm.open("sim:?motion=still&noise=%g" % noise) as dev:
        poses = [dev.wait_pose(1.0) for _ in range(300)]
        raw = dev.get_raw()
        stats = dev.stats()
    seq = [p.sequence for p in poses]
    assert all(b > a for a, b in zip(seq, seq[1:])), "wait_pose returned an old pose"
    host = [p.host_time_ns for p in poses]
    assert all(b > a for a, b in zip(host, host[1:]))
    # Each pot reads with std `noise`; four cables share the x error, and x
    # moves by dl * L / x: std(x) = noise * L / (2 x). 300 samples (correlated
    # by nothing) estimate a std within ~4 %; allow 25 %.
    L = statistics.mean(raw.lengths_mm)
    expect = noise * L / (2 * 50.0)
    got = statistics.stdev(p.position[0] for p in poses)
    assert got == pytest.approx(expect, rel=0.25)
    assert stats.reports >= 300 and stats.malformed == 0
    for p in poses:
        assert math.isclose(math.sqrt(sum(q * q for q in p.orientation)), 1.0, abs_tol=2.0 / 16384)


def test_wait_pose_timeout_and_argument_checks():
    with cdm.open("sim:?rate=2") as dev:  # a report every 500 ms
        dev.wait_pose(2.0)
        t0 = time.monotonic()
        with pytest.raises(cdm.CdmError) as e:
            dev.wait_pose(0.05)
        assert e.value.code == cdm.CDM_ERR_TIMEOUT
        assert 0.04 <= time.monotonic() - t0 < 1.0
        with pytest.raises(ValueError, match="timeout"):
            dev.wait_pose(-1)
        # after beyond the C call's 64 bits is refused, not wrapped to 0
        with pytest.raises(ValueError, match="after"):
            dev.wait_pose(0.01, after=2**64)
        # an infinite timeout is no limit (it raised OverflowError)
        p = dev.wait_pose(float("inf"))
        assert p.host_sequence > 0


def test_stale_pose_is_returned_with_its_flag():
    with cdm.open("sim:?stall_after=5", stale_timeout_us=20000) as dev:
        dev.wait_pose(1.0)
        time.sleep(0.15)
        p = dev.get_pose()
    assert p.status == cdm.CDM_ERR_STALE and p.is_stale and not p.is_fresh
    assert p.sequence == 4


def test_end_of_stream_is_returned_with_its_flag():
    uri = "sim:?motion=jig&jig_n=1&jig_heights=50&jig_samples=5&jig_transit=1&realtime=0"
    with cdm.open(uri) as dev:
        deadline = time.monotonic() + 5
        p = dev.wait_pose(1.0)
        while not p.is_end_of_stream and time.monotonic() < deadline:
            p = dev.wait_pose(1.0)
    assert p.status == cdm.CDM_ERR_END_OF_STREAM and p.flags & cdm.CDM_POSE_END_OF_STREAM


def test_no_data_raises(lib, monkeypatch):
    # Before the first report cdm_get_pose returns NO_DATA with a zeroed pose:
    # the binding raises rather than hand out a pose at the origin.
    with cdm.open("sim:") as dev:
        monkeypatch.setattr(lib, "cdm_get_pose", lambda h, p: cdm.CDM_ERR_NO_DATA)
        with pytest.raises(cdm.CdmError) as e:
            dev.get_pose()
    assert e.value.code == cdm.CDM_ERR_NO_DATA and e.value.function == "cdm_get_pose"


def test_unsolvable_reports_raise_with_their_own_reason():
    # Every report saturated: NO_DATA with NO_POSITION. The error says so,
    # not what an earlier failing call (a missing calibration) said.
    with cdm.open("sim:?saturate=0:1000000") as dev:
        deadline = time.monotonic() + 5  # the first report: at once, unless the machine is loaded
        while time.monotonic() < deadline:
            with pytest.raises(cdm.CdmError) as e:
                dev.get_pose()
            if "no position yet" in str(e.value):
                break
            time.sleep(0.01)
        with pytest.raises(cdm.CdmError):
            cdm.Calibration.load("/nonexistent/cdm-test-calibration.json")
        with pytest.raises(cdm.CdmError) as e:
            dev.get_pose()
    assert e.value.code == cdm.CDM_ERR_NO_DATA
    assert "no position yet" in str(e.value) and "calibration" not in str(e.value)


@pytest.mark.parametrize("uri, exc", [("sim:\x00rate=5", ValueError), (b"sim:", TypeError), (5, TypeError)])
def test_uri_that_c_would_read_otherwise_is_refused(uri, exc):
    with pytest.raises(exc):
        cdm.open(uri)


def test_context_manager_and_idempotent_close():
    with cdm.open("sim:") as dev:
        assert not dev.closed
        dev.wait_pose(1.0)
    assert dev.closed
    dev.close()
    dev.close()
    with pytest.raises(cdm.CdmError) as e:
        dev.get_pose()
    assert e.value.code == cdm.CDM_ERR_INVALID_ARG and "closed" in str(e.value)


@pytest.mark.parametrize("uri, codes", [
    ("nosuchscheme:abc", (cdm.CDM_ERR_NO_DEVICE, cdm.CDM_ERR_INVALID_ARG)),
    ("sim:?frobnicate=1", (cdm.CDM_ERR_INVALID_ARG,)),
    ("replay:/nonexistent/cdm-test.rec", (cdm.CDM_ERR_NO_DEVICE, cdm.CDM_ERR_IO)),
])
def test_bad_uri_error_carries_code_and_names_the_uri(uri, codes):
    with pytest.raises(cdm.CdmError) as e:
        cdm.open(uri)
    err = e.value
    assert err.code in codes
    assert err.function == "cdm_open"
    assert uri in err.message and uri in str(err)
    assert err.detail and err.message.startswith(cdm._native.lib().cdm_strerror(err.code).decode())
    assert err.name in ("CDM_ERR_NO_DEVICE", "CDM_ERR_INVALID_ARG", "CDM_ERR_IO")


def test_on_sample_callback_sees_every_report_in_order():
    got = []
    lock = threading.Lock()

    def on_sample(s):
        with lock:
            got.append((s.pose.sequence, s.raw.sequence, len(s.report)))

    # realtime=0: the callback paces the simulation, so nothing may be dropped
    # however slow Python is (in real time, a loaded machine legitimately loses
    # reports, as the kernel's hidraw queue would).
    with cdm.open("sim:?realtime=0", on_sample=on_sample) as dev:
        for _ in range(5):
            gc.collect()  # the ctypes trampoline must survive collections
            dev.wait_pose(1.0)
    n = len(got)
    time.sleep(0.05)
    assert len(got) == n, "callback ran after close"
    assert n >= 5
    seqs = [g[0] for g in got]
    assert seqs == list(range(seqs[0], seqs[0] + n)), "reports skipped or out of order"
    assert all(g[0] == g[1] and g[2] > 0 for g in got)


def test_set_stale_timeout_and_error_detail():
    with cdm.open("sim:") as dev:
        dev.set_stale_timeout(0.2)
        dev.set_stale_timeout(0)
        with pytest.raises(ValueError):
            dev.set_stale_timeout(-1)
        assert isinstance(dev.error_detail(), str)


def test_stored_calibration_round_trip():
    blob = b'{"note": "stored by test_device"}'
    with cdm.open("sim:") as dev:
        dev.write_stored_calibration(blob)
        assert dev.read_stored_calibration() == blob
        big = b"x" * 10000  # larger than the first read buffer
        dev.write_stored_calibration(big)
        assert dev.read_stored_calibration() == big


def test_enumerate_without_devices_is_a_list():
    devs = cdm.enumerate()
    assert isinstance(devs, list)
    assert all(isinstance(d, cdm.DeviceInfo) for d in devs)


def test_wait_pose_after_returns_at_once_when_newer_exists():
    # No lost wake-up: a pose published while the caller was busy is handed
    # over at once by wait_pose(after=last.host_sequence).
    with cdm.open("sim:?rate=20") as dev:  # a report every 50 ms
        first = dev.wait_pose(2.0)
        assert first.host_sequence >= 1
        time.sleep(0.3)  # several poses published meanwhile
        t0 = time.monotonic()
        p = dev.wait_pose(2.0, after=first.host_sequence)
        assert time.monotonic() - t0 < 0.03, "waited although a newer pose existed"
        assert p.host_sequence > first.host_sequence
        q = dev.wait_pose(2.0, after=p.host_sequence)
        assert q.host_sequence > p.host_sequence
        with pytest.raises(ValueError, match="after"):
            dev.wait_pose(1.0, after=-1)
        s = dev.stats()
        assert s.sequence_jumps == 0 and s.out_of_order == 0 and s.replay_truncated_bytes == 0


def test_wait_pose_without_limit_is_interrupted_by_ctrl_c():
    # wait_pose(None) on a silent device waits in 100 ms slices, so SIGINT
    # (Ctrl-C) raises KeyboardInterrupt promptly instead of hanging in C.
    import signal
    import threading

    with cdm.open("sim:?stall_after=3") as dev:
        last = 0
        while last < 3:  # all the reports the stalled device will ever send
            last = dev.wait_pose(2.0, after=last).host_sequence
        timer = threading.Timer(0.3, lambda: signal.pthread_kill(threading.main_thread().ident, signal.SIGINT))
        t0 = time.monotonic()
        timer.start()
        try:
            with pytest.raises(KeyboardInterrupt):
                dev.wait_pose(None, after=last)
        finally:
            timer.cancel()
        waited = time.monotonic() - t0
        assert 0.25 < waited < 0.3 + 0.1 + 0.2, waited  # interrupt + one slice + scheduling


def test_velocity_on_the_circle():
    """Pose.velocity (since 1.1) on the sim's circle: speed 40 mm x 2 pi x
    0.25 Hz = 62.8 mm/s; within 8 mm/s (the ADC quantisation's difference
    noise after the 50 Hz filter is ~1.6 mm/s rms: 5 sigma)."""
    import math
    with cdm.open("sim:?motion=circle&noise=0&imu_noise=0&hall_noise=0") as dev:
        p = dev.wait_pose(1.0, after=0)
        while p.host_sequence < 150:
            p = dev.wait_pose(1.0, after=p.host_sequence)
        assert abs(p.velocity[0]) < 8.0
        assert math.hypot(p.velocity[1], p.velocity[2]) == pytest.approx(2 * math.pi * 0.25 * 40, abs=8.0)


def test_events_and_log():
    """on_event (since 1.1) sees a stall as "stale"; cdm.log.to_python routes
    libcdm's messages into logging (a failing call's detail at DEBUG)."""
    import logging
    seen = []
    with cdm.open("sim:?stall_after=30", on_event=lambda kind, text: seen.append((kind, text))) as dev:
        deadline = time.monotonic() + 2.0
        while not any(k == "stale" for k, _ in seen) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert dev.stats().reports > 0
    assert [k for k, _ in seen].count("stale") == 1, seen

    records = []

    class Grab(logging.Handler):
        def emit(self, record):
            records.append(record)

    logger = logging.getLogger("cdm.test")
    logger.setLevel(logging.DEBUG)
    logger.addHandler(Grab())
    cdm.log.to_python(logger)
    try:
        with pytest.raises(cdm.NoDeviceError):
            cdm.open("nosuch:")
    finally:
        cdm.log.stop()
    assert any(r.levelno == logging.DEBUG and "nosuch" in r.getMessage() for r in records)
    n = len(records)
    with pytest.raises(cdm.NoDeviceError):
        cdm.open("nosuch:")
    assert len(records) == n
