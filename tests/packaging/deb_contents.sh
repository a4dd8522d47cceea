#!/usr/bin/env bash
# What the .deb holds, without installing it (no root): cpack -G DEB, then
# dpkg-deb -x into a directory. No installed file may name the build
# machine's source or build directory (strings of binaries included); the
# Python package is where Debian's python3 imports it, and from there the
# packaged cdm runs `calib diagnose --report` with no clone on any path.
#   deb_contents.sh BUILD_DIR SOURCE_DIR WORKDIR
set -euo pipefail
build=$(cd "$1" && pwd -P) src=$(cd "$2" && pwd -P) work=$3
unset CDM_LIBRARY CDM_BUILD_DIR LD_LIBRARY_PATH PYTHONPATH PYTHON
rm -rf "$work" && mkdir -p "$work/root"
(cd "$build" && cpack -G DEB -B "$work" >/dev/null)
deb=$(ls "$work"/cdm_*.deb)
dpkg-deb -x "$deb" "$work/root"
root=$work/root
# Every file, binary or not: -a reads binaries as text, -F the paths literally.
bad=$(grep -rlaF -e "$src" -e "$build" "$root" || true)
if [ -n "$bad" ]; then
  echo "deb_contents: installed files name the build machine's paths ($src, $build):" >&2
  for f in $bad; do echo "  ${f#"$root"}: $(grep -aoF -e "$src" -e "$build" "$f" | sort -u | head -3 | tr '\n' ' ')" >&2; done
  exit 1
fi
test -f "$root/usr/lib/python3/dist-packages/cdm/report/__init__.py"
test -f "$root/usr/lib/python3/dist-packages/cdm/py.typed"
test ! -e "$root/usr/lib/python3/dist-packages/cdm/report.py"
test -f "$root/usr/share/doc/cdm/README.md" && test -f "$root/usr/share/doc/cdm/docs/bindings.md"
# Libraries in the multiarch directory; a man page for cdm and each subcommand.
test -f "$root/usr/lib/x86_64-linux-gnu/libcdm.so.1" || test -n "$(find "$root/usr/lib" -path '*-linux-gnu/libcdm.so.1')"
for page in cdm cdm-record cdm-calib cdm-calib-diagnose cdm-calib-check cdm-calib-plan cdm-bridge; do
  zcat "$root/usr/share/man/man1/$page.1.gz" | grep -q '^\.TH' || { echo "deb_contents: no man page $page.1.gz"; exit 1; }
done
if dpkg-deb -f "$deb" Homepage | grep -q .; then
  dpkg-deb -f "$deb" Homepage | grep -qv 'example\.invalid'
fi
# The packaged cdm, its library and Python package only (the dynamic linker
# finds the library through LD_LIBRARY_PATH here, as ldconfig would under /usr).
libdir=$(dirname "$(find "$root/usr/lib" -name 'libcdm.so.1' | head -1)")
cd "$work"
LD_LIBRARY_PATH=$libdir "$root/usr/bin/cdm" calib simulate "$work/jig.csv" --holes 5 --heights 40,60 --samples 5 >/dev/null
LD_LIBRARY_PATH=$libdir "$root/usr/bin/cdm" calib diagnose "$work/jig.csv" --quiet --no-candidates --report "$work/rep"
test -f "$work/rep/index.html"
echo "deb_contents: no build path in $(find "$root" -type f | wc -l) files; --report from the package alone"
