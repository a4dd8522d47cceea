#!/usr/bin/env bash
# Configures and builds into ./build (or $CDM_BUILD_DIR).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${CDM_BUILD_DIR:-build}
if [ ! -f "$BUILD/build.ninja" ]; then
  cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPython3_EXECUTABLE="$(command -v python3)" \
    -DCDM_DDS=ON # scripts/setup.sh installs Cyclone DDS: without it, fail here
fi
cmake --build "$BUILD" -j"$(nproc)"
