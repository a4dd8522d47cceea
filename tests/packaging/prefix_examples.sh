#!/usr/bin/env bash
# cmake --install into a fresh prefix, then the examples exactly as their
# READMEs say, from a directory outside the tree, with no library variables.
set -euo pipefail
build=$1 src=$2 prefix=$3
unset CDM_LIBRARY CDM_BUILD_DIR LD_LIBRARY_PATH MONO_PATH
rm -rf "$prefix" && mkdir -p "$prefix"
cmake --install "$build" --prefix "$prefix" >/dev/null
work=$(mktemp -d) && trap 'rm -rf "$work"' EXIT
cd "$work"
# The libraries' directory: the multiarch one (lib/x86_64-linux-gnu) on Debian.
libdir=$(dirname "$(find "$prefix" -name libcdm.so.1 | head -1)")
case "$libdir" in "$prefix"/lib/*-linux-gnu) ;; *) echo "prefix: libcdm in $libdir, not the multiarch directory"; exit 1;; esac
# examples/c/README.md: the pkg-config command line.
export PKG_CONFIG_PATH="$libdir/pkgconfig"
# shellcheck disable=SC2046
cc -o teleop_loop "$src/examples/c/teleop_loop.c" $(pkg-config --cflags --libs cdm) -lm \
   -Wl,-rpath,"$libdir"
./teleop_loop sim: --seconds 1 | grep "loop period: mean" >/dev/null
# examples/c/README.md: the CMake way (find_package(cdm)).
cmake -S "$src/examples/c" -B cbuild -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
cmake --build cbuild >/dev/null
./cbuild/teleop_loop sim: --seconds 1 | grep "loop period: mean" >/dev/null
# examples/csharp/README.md: mcs against the installed Cdm.dll, mono with
# MONO_PATH only (the installed Cdm.dll.config names the installed library).
if command -v mcs >/dev/null && [ -f "$libdir/cdm/csharp/Cdm.dll" ]; then
  mcs -nologo -r:"$libdir/cdm/csharp/Cdm.dll" -out:TeleopLoop.exe "$src/examples/csharp/TeleopLoop.cs"
  MONO_PATH="$libdir/cdm/csharp" mono TeleopLoop.exe sim: --seconds 1 | grep "loop period" >/dev/null
fi
echo "prefix examples: ok"
