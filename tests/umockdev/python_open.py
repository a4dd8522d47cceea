"""cdm.open on the emulated master (run by with_master under umockdev-wrapper):
the Python binding over the real libhidapi-hidraw."""
import math
import sys

import cdm

with cdm.open("hid:/dev/hidraw0") as dev:
    info = dev.info()
    assert info.serial == "UMOCK0001", info.serial
    seqs = set()
    for _ in range(200):
        p = dev.wait_pose(timeout=1.0)
        assert all(math.isfinite(x) for x in p.position), p.position
        seqs.add(p.sequence)
        if len(seqs) >= 20:
            break
    st = dev.stats()
    assert len(seqs) >= 20, len(seqs)
    assert st.malformed == 0, st
print("python: serial %s, %d distinct poses, %d reports" % (info.serial, len(seqs), st.reports))
print("1 passed, 0 failed")
sys.exit(0)
