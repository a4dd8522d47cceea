#!/usr/bin/env bash
# cpack -G DEB, dpkg -i (root on a throw-away CI machine: the test is about
# what a user gets from apt, /usr/lib and pkg-config's default search path
# included, which dpkg -x into a temporary root would not show), a C program
# outside the tree built with `pkg-config --cflags --libs cdm`, a CMake
# consumer with find_package(cdm), both run on sim: with no environment
# variables; then dpkg -r.
set -euo pipefail
build=$1 work=$2
[ "$(id -u)" -eq 0 ] || { echo "deb: needs root (dpkg -i); skipped"; exit 77; }
if [ "$(dpkg-query -W -f='${db:Status-Status}' cdm 2>/dev/null || true)" = installed ]; then
  echo "deb: a cdm package is already installed; not touching it"; exit 77
fi
unset CDM_LIBRARY CDM_BUILD_DIR LD_LIBRARY_PATH PKG_CONFIG_PATH CMAKE_PREFIX_PATH
rm -rf "$work" && mkdir -p "$work"
(cd "$build" && cpack -G DEB -B "$work" >/dev/null)
deb=$(ls "$work"/cdm_*.deb)
dpkg-deb -f "$deb" Depends | grep libhidapi-hidraw0 >/dev/null
trap 'dpkg --purge cdm >/dev/null || true' EXIT
apt-get install -y -qq "$deb" >/dev/null 2>&1 || dpkg -i "$deb"
test -f /usr/lib/udev/rules.d/70-cdm.rules
command -v cdm >/dev/null
cd "$work"
cat > use.c <<'C'
#include <cdm/cdm.h>
#include <stdio.h>
int main(void) {
  cdm_device *d = NULL;
  int rc = cdm_open("sim:", &d);
  if (rc != 0) { fprintf(stderr, "cdm_open: %d\n", rc); return 1; }
  cdm_close(d);
  printf("deb: open sim: ok\n");
  return 0;
}
C
# shellcheck disable=SC2046
cc -o use use.c $(pkg-config --cflags --libs cdm)
./use
mkdir -p cm && cp use.c cm/ && cat > cm/CMakeLists.txt <<'CM'
cmake_minimum_required(VERSION 3.16)
project(use C)
find_package(cdm 1 REQUIRED)
add_executable(use use.c)
target_link_libraries(use PRIVATE cdm::cdm)
CM
cmake -S cm -B cm/build >/dev/null && cmake --build cm/build >/dev/null
./cm/build/use
