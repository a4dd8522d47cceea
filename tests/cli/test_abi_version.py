"""The exported symbols carry the version nodes libcdm.map promises (stable
CDM_1 / CDM_1.1, experimental CDM_EXPERIMENTAL_<CDM_EXPERIMENTAL_VERSION>),
and every copy of the version number agrees with CMakeLists.txt."""
import os
import re
import subprocess

import pytest

from conftest import cdm

SRC = os.environ.get("CDM_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
VERSION = os.environ.get("CDM_PROJECT_VERSION", "")


def read(*parts):
    with open(os.path.join(SRC, *parts), encoding="utf-8") as f:
        return f.read()


def header_functions():
    """(name, experimental, since) of every CDM_API function in cdm.h; since
    is the stable minor version that added it ("1.1", "1.2") or None (1.0)."""
    text = read("include", "cdm", "cdm.h")
    exp_at = text.index("#if defined(CDM_EXPERIMENTAL)")
    out = []
    for m in re.finditer(r"CDM_API\s+[^;(]*?\b(cdm_\w+)\s*\(", text):
        doc = text[max(0, text.rfind("/**", 0, m.start())):m.start()]
        # A function added in 1.x says so first thing in its comment
        # ("since 1.1. ..."); a later mention of a version in the text (a new
        # flag it may return) does not move it.
        since = re.match(r"/\*\*\s*(\*\s*)?since (1\.[1-9]\d*)\b", doc)
        out.append((m.group(1), m.start() > exp_at, since.group(2) if since else None))
    return out


def exported():
    """{name: version node} of the cdm_* symbols libcdm exports."""
    lib = os.path.realpath(os.environ["CDM_LIBRARY"])
    objdump = os.environ.get("CDM_OBJDUMP") or "objdump"
    text = subprocess.run([objdump, "-T", lib], capture_output=True, text=True, check=True).stdout
    out = {}
    for line in text.splitlines():
        f = line.split()
        if f and f[-1].startswith("cdm_") and " DF " in line and ".text" in line:
            out[f[-1]] = f[-2]
    return out


def test_version_nodes():
    exp_version = re.search(r"#define CDM_EXPERIMENTAL_VERSION (\d+)", read("include", "cdm", "cdm.h")).group(1)
    syms = exported()
    funcs = header_functions()
    assert len(funcs) > 40
    for name, experimental, since in funcs:
        want = "CDM_EXPERIMENTAL_" + exp_version if experimental else ("CDM_" + since if since else "CDM_1")
        assert syms.get(name) == want, "%s: node %s, want %s" % (name, syms.get(name), want)
    # Nothing but the header's functions leaves the library.
    assert set(syms) == {n for n, _, _ in funcs}


def test_version_copies_agree():
    assert re.fullmatch(r"\d+\.\d+\.\d+", VERSION)
    major, minor, patch = VERSION.split(".")
    h = read("include", "cdm", "cdm.h")
    for part, value in (("MAJOR", major), ("MINOR", minor), ("PATCH", patch)):
        assert re.search(r"#define CDM_VERSION_%s %s\b" % (part, value), h), part
    # The wheel reads its version from CMakeLists.txt (scikit-build-core's
    # regex provider): no copy of its own to drift.
    pyproject = read("pyproject.toml")
    assert re.search(r'^dynamic = \["version"\]', pyproject, re.M) and "CMakeLists.txt" in pyproject
    assert 'AssemblyVersion("%s.0")' % VERSION in read("bindings", "csharp", "src", "AssemblyInfo.cs")
    py = read("bindings", "python", "cdm", "constants.py")
    for part, value in (("MAJOR", major), ("MINOR", minor), ("PATCH", patch)):
        assert re.search(r"^CDM_VERSION_%s = %s$" % (part, value), py, re.M), "constants.py " + part
    assert cdm("--version").stdout.strip() == "cdm " + VERSION


def test_python_version_is_the_librarys():
    env = dict(os.environ, PYTHONPATH=os.path.join(SRC, "bindings", "python"))
    r = subprocess.run([os.environ.get("PYTHON", "python3"), "-c", "import cdm; print(cdm.__version__)"],
                       capture_output=True, text=True, env=env, check=True)
    assert r.stdout.strip() == VERSION
