"""The binding as a modern Python library: exceptions that
are also the built-ins a Python user catches, a Diagnosis that saves and
loads its JSON, and the py.typed marker (ctest python_mypy runs mypy --strict)."""
import os
import subprocess
import sys

import pytest

import cdm
from conftest import simulate_jig

PKG_DIR = os.path.join(os.path.dirname(__file__), "..", "..", "bindings", "python")
DEVICE_JSON = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples", "device.json")


def test_errors_are_the_builtins_too(tmp_path):
    with pytest.raises(FileNotFoundError) as e:
        cdm.open("nosuch:")
    assert isinstance(e.value, cdm.NoDeviceError) and e.value.code == cdm.CDM_ERR_NO_DEVICE
    with pytest.raises(ValueError) as e:
        cdm.open("sim:?rate=abc")
    assert isinstance(e.value, cdm.InvalidArgumentError) and "rate" in str(e.value)
    # A number in a message reads as a person writes it, not "1.000000".
    assert ".000000" not in str(e.value)
    with pytest.raises(FileNotFoundError) as e:
        cdm.Calibration.load(tmp_path / "missing.json")
    assert isinstance(e.value, cdm.CdmError) and "missing.json" in str(e.value)
    bad = tmp_path / "bad.json"
    bad.write_text("{\n  \"format\": ,\n}\n")
    with pytest.raises(ValueError) as e:
        cdm.Calibration.load(bad)
    assert isinstance(e.value, cdm.ParseError) and "bad.json:2:" in str(e.value)
    # A timeout is a TimeoutError: a master that stalls after 5 reports.
    with cdm.open("sim:?stall_after=5") as dev:
        with pytest.raises(TimeoutError) as e:
            for _ in range(100):
                dev.wait_pose(0.2)
        assert isinstance(e.value, cdm.CdmTimeoutError)
    # Every subclass is still built by CdmError(code, ...), and pickles.
    import pickle
    err = cdm.CdmError(cdm.CDM_ERR_DISCONNECTED, "gone")
    assert isinstance(err, ConnectionError) and type(pickle.loads(pickle.dumps(err))) is cdm.DisconnectedError


def test_diagnosis_saves_and_loads(tmp_path):
    ds = simulate_jig(tmp_path / "ds.csv", "--effects", "exit_pulley", "--effect-seed", "1", "--holes", "5",
                      "--heights", "40,60", "--samples", "5")
    d = cdm.diagnose(ds, DEVICE_JSON, effects=["exit_pulley"], candidates=False, validation=False)
    assert isinstance(d, cdm.Diagnosis) and d.verdict
    path = tmp_path / "diag.json"
    text = d.to_json(path, indent=1)
    assert path.read_text() == text
    back = cdm.load_diagnosis(path)
    assert isinstance(back, cdm.Diagnosis) and back.verdict == d.verdict
    assert back["error_mm"] == d["error_mm"]
    np = pytest.importorskip("numpy")
    assert np.array_equal(back["positions"]["ref"], d["positions"]["ref"])
    # Only over a regular file: a directory is refused, nothing written.
    with pytest.raises(OSError):
        d.to_json(tmp_path)  # a directory
    (tmp_path / "not.json").write_text("[1, 2]")
    with pytest.raises(ValueError):
        cdm.load_diagnosis(tmp_path / "not.json")


def test_exports_and_types():
    for name in cdm.__all__:
        assert hasattr(cdm, name), name
    assert os.path.exists(os.path.join(PKG_DIR, "cdm", "py.typed"))
    # `mypy --strict` over the package and the examples is its own ctest, python_mypy.


SIGINT_SCRIPT = """
import os, signal, sys, threading, cdm
threading.Timer(0.1, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
try:
    cdm.diagnose(sys.argv[1], sys.argv[2])
    print("finished")
except KeyboardInterrupt:
    print("interrupted")
"""


def test_ctrl_c_cancels_a_diagnosis(tmp_path):
    """SIGINT during cdm.diagnose (a single long C call) cancels it at the
    next fit iteration and raises KeyboardInterrupt; the handler is restored."""
    # 62,500 rows: the diagnosis takes over a second here, far beyond the 0.1 s
    # at which the signal arrives.
    ds = simulate_jig(tmp_path / "ds.csv", "--effects", "exit_pulley", "--samples", "20")
    r = subprocess.run([sys.executable, "-c", SIGINT_SCRIPT, str(ds), DEVICE_JSON], capture_output=True, text=True,
                       env=dict(os.environ), timeout=120)
    assert r.stdout.strip() == "interrupted", r.stdout + r.stderr
