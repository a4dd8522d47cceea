#!/usr/bin/env bash
# A libcdm.so.1 beside Cdm.dll whose own dependency (libcdm_test_absent.so) is
# not on any path: Cdm's DllNotFoundException must name that dependency, not
# just libcdm.so.1. The stand-in is a tiny library linked against a
# dependency that is deleted after linking.
#   missing_dependency.sh CC MONO CdmTests.exe Cdm.dll-dir WORKDIR
set -euo pipefail
cc=$1 mono=$2 exe=$3 dlldir=$4 work=$5
unset LD_LIBRARY_PATH MONO_PATH
rm -rf "$work" && mkdir -p "$work/dep" "$work/app"
echo 'int cdm_test_absent(void) { return 1; }' > "$work/dep/dep.c"
echo 'int cdm_test_absent(void); int cdm_version_number(void) { return cdm_test_absent(); }' > "$work/lib.c"
"$cc" -shared -fPIC -o "$work/dep/libcdm_test_absent.so" "$work/dep/dep.c"
"$cc" -shared -fPIC -Wl,-soname,libcdm.so.1 -o "$work/app/libcdm.so.1" "$work/lib.c" -L"$work/dep" -lcdm_test_absent
rm -r "$work/dep"
cp "$exe" "$dlldir/Cdm.dll" "$dlldir/Cdm.dll.config" "$work/app/"
cd "$work/app" && exec "$mono" ./CdmTests.exe libcdm_test_absent.so missing_dependency
