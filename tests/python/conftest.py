import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))

import cdm  # noqa: E402


@pytest.fixture(scope="session")
def lib():
    """The libcdm under test ($CDM_LIBRARY, set by ctest)."""
    return cdm._native.lib()


def simulate_jig(out, *args):
    """`cdm calib simulate OUT ARGS...` through the built CLI ($CDM_CLI, set
    by ctest; the test is skipped without it), as an argument vector."""
    cli = os.environ.get("CDM_CLI")
    if not cli:
        pytest.skip("CDM_CLI (the built `cdm` program) is not set; ctest sets it")
    import subprocess
    subprocess.run([cli, "calib", "simulate", os.fspath(out), *map(str, args)], check=True, capture_output=True)
    return out
