#!/usr/bin/env bash
# The build as users run it: the library and the `cdm` command configured
# in Release with the default options (CDM_DDS=AUTO, no CDM_* option set),
# then once more without the DDS bridge (-DCDM_DDS=OFF). Warnings are
# errors here (CI), as in the developers' build; a user's build keeps them
# warnings (CDM_WERROR defaults to OFF). With ccache (scripts/setup.sh
# installs it) the library's objects are those of a Release test build
# configured the same way (CDM_BUILD_TYPE=Release scripts/build.sh): only
# what differs is compiled.
set -euo pipefail
cd "$(dirname "$0")/.."
launcher=()
command -v ccache >/dev/null 2>&1 && launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
# Paths under the tree are hashed relative to each build directory, so two
# build directories of the same configuration share their objects.
export CCACHE_BASEDIR="$PWD"
for variant in default nodds; do
  dir=build-release-$variant
  extra=()
  [ "$variant" = nodds ] && extra=(-DCDM_DDS=OFF)
  cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCDM_WERROR=ON "${launcher[@]}" "${extra[@]}" > /dev/null
  cmake --build "$dir" --target cdm cdm-cli -j"$(nproc)"
  "$dir/src/cli/cdm" --version
done
