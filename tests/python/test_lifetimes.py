"""Device lifetimes against re-entrancy (docs/reliability.md, "Callbacks"):
close() from the device's own callbacks and from the log sink, close() while
another thread waits, and what a callback may call. One test per row of the
table. Bounded joins: a hang fails the test instead of hanging the suite."""
import logging
import os
import threading
import time

import pytest

import cdm
from cdm import CdmError, Error


def _threads():
    return len(os.listdir("/proc/self/task"))


def _until(pred, seconds=3.0):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.005)
    return pred()


def test_close_inside_on_sample_callback():
    before = _threads()
    state = {"dev": None, "closed": 0, "after": 0, "error": None}

    def on_sample(_s):
        dev = state["dev"]
        if dev is None:
            return
        if state["closed"]:
            state["after"] += 1
            return
        try:
            dev.close()
        except BaseException as e:  # noqa: BLE001 - the test reports it
            state["error"] = e
        state["closed"] += 1

    state["dev"] = cdm.open("sim:?rate=1000", on_sample=on_sample)
    assert _until(lambda: state["closed"] == 1)
    assert state["error"] is None
    assert state["dev"].closed
    # The reader thread (and the helper that freed the handle) are gone.
    assert _until(lambda: _threads() <= before)
    assert state["after"] == 0
    with pytest.raises(CdmError):
        state["dev"].get_pose()


def test_close_inside_on_event_callback():
    state = {"dev": None, "closed": 0, "error": None}

    def on_event(kind, _text):
        dev = state["dev"]
        if dev is None or kind != "stale" or state["closed"]:
            return
        try:
            dev.close()
        except BaseException as e:  # noqa: BLE001
            state["error"] = e
        state["closed"] += 1

    before = _threads()
    state["dev"] = cdm.open("sim:?rate=1000&stall_after=20", on_event=on_event)
    assert _until(lambda: state["closed"] == 1)
    assert state["error"] is None and state["dev"].closed
    assert _until(lambda: _threads() <= before)


def test_close_inside_log_sink():
    """The log sink (a rejected report's warning, on the reader thread)
    closes the device."""
    state = {"dev": None, "closed": 0, "error": None}

    class Closer(logging.Handler):
        def emit(self, record):
            dev = state["dev"]
            if dev is None or "rejected" not in record.getMessage() or state["closed"]:
                return
            state["closed"] += 1
            try:
                dev.close()
            except BaseException as e:  # noqa: BLE001
                state["error"] = e

    logger = logging.getLogger("cdm.test_lifetimes")
    logger.setLevel(logging.DEBUG)
    logger.propagate = False
    handler = Closer()
    logger.addHandler(handler)
    cdm.log.to_python(logger)
    try:
        state["dev"] = cdm.open("sim:?rate=1000&malformed=short:50")
        assert _until(lambda: state["closed"] == 1)
    finally:
        cdm.log.stop()
        logger.removeHandler(handler)
    assert state["error"] is None and state["dev"].closed


@pytest.mark.parametrize("timeout", [None, 30.0])
def test_close_while_another_thread_waits(timeout):
    """A waiter on a stalled device: close() wakes it with CDM_ERR_CLOSED (it
    kept calling into the freed handle and returned a pose)."""
    dev = cdm.open("sim:?rate=1000&stall_after=10")
    first = dev.wait_pose(timeout=2.0)
    time.sleep(0.1)  # the device is silent from here on
    last = dev.get_pose()
    got = {}

    def waiter():
        try:
            got["pose"] = dev.wait_pose(timeout=timeout, after=last.host_sequence)
        except CdmError as e:
            got["error"] = e

    t = threading.Thread(target=waiter)
    t.start()
    time.sleep(0.2)
    closer = threading.Thread(target=dev.close)
    closer.start()
    closer.join(5)
    t.join(5)
    assert not closer.is_alive(), "close() blocked"
    assert not t.is_alive(), "the waiter was not woken by close()"
    assert "pose" not in got, "a closed device handed out a pose"
    assert got["error"].code == Error.CDM_ERR_CLOSED
    assert dev.closed and first.host_sequence > 0


def test_wait_pose_inside_own_callback_raises_at_once():
    state = {"dev": None, "rc": None, "ms": None}

    def on_sample(_s):
        dev = state["dev"]
        if dev is None or state["rc"] is not None:
            return
        t0 = time.monotonic()
        try:
            dev.wait_pose(timeout=5.0)
            state["rc"] = 0
        except CdmError as e:
            state["rc"] = e.code
        state["ms"] = (time.monotonic() - t0) * 1000.0

    with cdm.open("sim:?rate=200", on_sample=on_sample) as dev:
        state["dev"] = dev
        assert _until(lambda: state["rc"] is not None)
    assert state["rc"] == Error.CDM_ERR_INVALID_ARG
    assert state["ms"] < 1000.0  # at once, not after the 5 s wait


def test_callback_may_call_its_device():
    state = {"dev": None, "done": False, "error": None}

    def on_sample(_s):
        dev = state["dev"]
        if dev is None or state["done"]:
            return
        try:
            dev.get_pose()
            dev.get_raw()
            dev.info()
            dev.stats()
            dev.error_detail()
            dev.set_calibration(None)
            dev.set_stale_timeout(0)
        except BaseException as e:  # noqa: BLE001
            state["error"] = e
        state["done"] = True

    with cdm.open("sim:?rate=1000", on_sample=on_sample) as dev:
        state["dev"] = dev
        assert _until(lambda: state["done"])
    assert state["error"] is None


def test_calls_racing_close_never_touch_a_freed_handle():
    """Eight threads call get_pose / wait_pose / stats while another closes:
    each call either works or raises CdmError (closed), never crashes."""
    dev = cdm.open("sim:?rate=1000")
    dev.wait_pose(timeout=2.0)
    bad = []
    stop = threading.Event()

    def hammer(i):
        while not stop.is_set():
            try:
                if i % 3 == 0:
                    dev.get_pose()
                elif i % 3 == 1:
                    dev.wait_pose(timeout=0.05)
                else:
                    dev.stats()
            except CdmError as e:
                if e.code not in (Error.CDM_ERR_INVALID_ARG, Error.CDM_ERR_CLOSED, Error.CDM_ERR_TIMEOUT):
                    bad.append(e)
            except BaseException as e:  # noqa: BLE001
                bad.append(e)

    ts = [threading.Thread(target=hammer, args=(i,)) for i in range(8)]
    for t in ts:
        t.start()
    time.sleep(0.2)
    dev.close()
    time.sleep(0.05)
    stop.set()
    for t in ts:
        t.join(5)
    assert not any(t.is_alive() for t in ts)
    assert not bad, bad[:3]
