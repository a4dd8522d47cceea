#!/usr/bin/env python3
"""How long each stage of a cdm command took, from its progress lines.

    scripts/progress_times.py build/src/cli/cdm calib diagnose X.csv

Runs the command (an argument vector, no shell) with its standard output
discarded, reads the progress it writes to standard error (lines ended by
\\r or \\n) and prints, for each line, the time since the start at which the
next one came and how long it stood: the time spent in that stage. By hand,
for docs/performance.md; one run is one sample (the machine's load moves it).
"""
import subprocess
import sys
import time


def main(argv):
    if not argv:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    t0 = time.monotonic()
    try:
        p = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    except OSError as e:
        print(f"progress_times.py: cannot run {argv[0]}: {e.strerror}", file=sys.stderr)
        return 127
    buf, last, msg = b"", t0, "start"
    while True:
        c = p.stderr.read(1)
        if not c:
            break
        if c in b"\r\n":
            if buf.strip():
                now = time.monotonic()
                print(f"{now - t0:7.3f} s  {now - last:6.3f} s  {msg}")
                last, msg = now, buf.decode(errors="replace").strip()
            buf = b""
        else:
            buf += c
    now = time.monotonic()
    print(f"{now - t0:7.3f} s  {now - last:6.3f} s  {msg}")
    return p.wait()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
