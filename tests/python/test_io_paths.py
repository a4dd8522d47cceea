"""Paths and names handed to C: an embedded NUL is a ValueError, never a
silently shortened path ("a\\x00b" must not open "a")."""
import pytest

import cdm
from cdm import _native


def test_path_with_nul_is_value_error(tmp_path):
    (tmp_path / "a").write_text("{}")
    with pytest.raises(ValueError, match="NUL"):
        cdm.Calibration.load(str(tmp_path / "a") + "\x00b")


def test_diagnose_paths_with_nul_are_value_errors(tmp_path):
    with pytest.raises(ValueError, match="dataset path contains a NUL"):
        cdm.diagnose(str(tmp_path / "d.csv") + "\x00x", str(tmp_path / "dev.json"))


def test_c_path_accepts_str_bytes_pathlike(tmp_path):
    assert _native.c_path("abc") == b"abc"
    assert _native.c_path(b"abc") == b"abc"
    assert _native.c_path(tmp_path) == bytes(str(tmp_path), "utf-8")
    with pytest.raises(ValueError):
        _native.c_path(b"a\x00b")


def test_missing_calibration_is_io_error_with_reason(tmp_path):
    with pytest.raises(cdm.CdmError) as e:
        cdm.Calibration.load(tmp_path / "none.json")
    assert "No such file or directory" in str(e.value)
