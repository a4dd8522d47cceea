#!/usr/bin/env bash
# Configures and builds into ./build (or $CDM_BUILD_DIR).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${CDM_BUILD_DIR:-build}
TYPE=${CDM_BUILD_TYPE:-RelWithDebInfo} # CI: Release, the build users run (scripts/release_check.sh)
# The developers' build: warnings are errors (CDM_WERROR; a user's build
# keeps them warnings). ccache, when installed, makes a rebuild after a
# small change take seconds per unchanged object.
launcher=()
command -v ccache >/dev/null 2>&1 && launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
# Paths under the tree are hashed relative to each build directory, so two
# build directories of the same configuration share their objects.
export CCACHE_BASEDIR="$PWD"
if [ ! -f "$BUILD/build.ninja" ]; then
  cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE="$TYPE" -DPython3_EXECUTABLE="$(command -v python3)" \
    -DCDM_WERROR=ON "${launcher[@]}" \
    -DCDM_DDS=ON # scripts/setup.sh installs Cyclone DDS: without it, fail here
fi
cmake --build "$BUILD" -j"$(nproc)"
