import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))

import cdm  # noqa: E402


@pytest.fixture(scope="session")
def lib():
    """The libcdm under test ($CDM_LIBRARY, set by ctest)."""
    return cdm._native.lib()
