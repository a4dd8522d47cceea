"""Finding libcdm: the order of the candidates, and an error that lists them."""
import ctypes.util
import os
import subprocess
import sys

import pytest

import cdm
from cdm import _native

PKG = os.path.dirname(os.path.abspath(cdm.__file__))


def test_candidate_order():
    c = [p for p, _ in _native.candidates({"CDM_LIBRARY": "/x/libcdm.so.1", "CDM_BUILD_DIR": "/b"})]
    assert c[0] == "/x/libcdm.so.1"
    assert c[1] == os.path.join(PKG, "libcdm.so.1")
    assert os.path.join("/b", "src", "libcdm.so.1") in c
    assert c.index(os.path.join("/b", "src", "libcdm.so.1")) > c.index(os.path.join(PKG, "libcdm.so.1"))
    assert c[-1] == "libcdm.so.1"


def test_override_wins(lib):
    assert os.path.samefile(lib.path, os.environ["CDM_LIBRARY"])


def test_failure_lists_every_path_tried(tmp_path):
    if ctypes.util.find_library("cdm"):
        pytest.skip("a system libcdm is installed: the system fallback would load it")
    env = dict(os.environ, CDM_LIBRARY=str(tmp_path / "nope" / "libcdm.so.1"), CDM_BUILD_DIR=str(tmp_path / "b"))
    r = subprocess.run([sys.executable, "-c", "import cdm; cdm.version()"], env=env, capture_output=True, text=True)
    assert r.returncode != 0
    assert "LibraryNotFoundError" in r.stderr
    for path in (env["CDM_LIBRARY"], os.path.join(PKG, "libcdm.so.1"), os.path.join(env["CDM_BUILD_DIR"], "src",
                                                                                       "libcdm.so.1"), "libcdm.so.1"):
        assert path in r.stderr, r.stderr


def test_not_libcdm_is_refused():
    libm = ctypes.util.find_library("m")
    with pytest.raises(cdm.LibraryNotFoundError) as e:
        _native.load([(libm, "test")])
    assert "not libcdm" in str(e.value) and libm in str(e.value)
    assert e.value.tried[0][0].startswith(libm)


def test_missing_function_raises_cdm_error():
    m = _native._Missing("cdm_frobnicate", "/some/libcdm.so.1")
    with pytest.raises(cdm.CdmError) as e:
        m(1, 2)
    assert e.value.code == cdm.CDM_ERR_UNSUPPORTED and "cdm_frobnicate" in str(e.value)
