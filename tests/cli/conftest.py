"""Helpers for driving the built `cdm` binary with argument vectors."""
import os
import subprocess

import pytest

CLI = os.environ.get("CDM_CLI", "")


def cdm(*args, timeout=120, **kw):
    """Runs `cdm ARGS...` (no shell) and returns the CompletedProcess."""
    return subprocess.run([CLI, *args], capture_output=True, text=True, timeout=timeout, **kw)


@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory):
    """A small simulated jig dataset (9 x 9 holes, 3 heights, 20 samples)."""
    path = tmp_path_factory.mktemp("data") / "jig.csv"
    r = cdm("calib", "simulate", str(path), "--holes", "9", "--heights", "30,50,70", "--samples", "20",
            "--effects", "cable_offset")
    assert r.returncode == 0, r.stderr
    return path
