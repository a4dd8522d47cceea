#!/usr/bin/env bash
# hidden_env.sh TREE -- CMD [ARG...]: runs CMD in a private mount namespace
# where TREE (the source tree, with any build tree in it) is an empty
# directory and the shared libraries of nlopt and hidapi are empty files, so
# a program finds neither the project's sources nor those libraries: what a
# machine with nothing of them installed gives. Root only (mount namespaces);
# exit status 77 (skipped) where the namespace cannot be made.
set -euo pipefail
if [ "${1:-}" != "--inside" ]; then
  unshare --mount --propagation private true 2>/dev/null || {
    echo "hidden_env: cannot make a mount namespace here (not root?)"
    exit 77
  }
  exec unshare --mount --propagation private -- "$0" --inside "$@"
fi
shift
tree=$1
shift
[ "${1:-}" = "--" ] && shift
mount -t tmpfs -o size=1m,mode=0755 none "$tree"
empty=$(mktemp)
hidden=0
for name in libnlopt.so libhidapi-hidraw.so libhidapi-libusb.so; do
  # Every file the dynamic linker's cache names for the library, by its real path.
  while read -r path; do
    real=$(readlink -f "$path")
    [ -f "$real" ] || continue
    mount --bind "$empty" "$real"
    hidden=$((hidden + 1))
  done < <(ldconfig -p | sed -n "s|^[[:space:]]*$name[^ ]* (.*) => ||p")
done
echo "hidden_env: $tree empty, $hidden library files of nlopt and hidapi empty"
exec "$@"
