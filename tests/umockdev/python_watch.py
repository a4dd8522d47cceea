"""cdm.watch on the emulated master (run by `with_master --replug 300,400
--after-output arrived` under umockdev-wrapper: the unplug comes 300 ms after
this program prints its first event): the master present at the start
arrives, leaves at the unplug and arrives again at the replug, through the
Python binding's callback on libcdm's watcher thread."""
import sys
import threading
import time

import cdm

seen = []
done = threading.Event()


def told(kind, info):
    seen.append((kind, info.uri, info.serial))
    print("watch event: %s %s" % (kind, info.uri), flush=True)  # with_master's cue
    if len(seen) >= 3:
        done.set()


with cdm.watch(told) as w:
    # Bounded wait for something to happen at all (a loaded machine); the
    # replug comes 0.7 s after the first event.
    done.wait(10.0)
assert w.closed
n = len(seen)
time.sleep(0.2)
assert len(seen) == n, "callback after close: %r" % (seen,)
want = [("arrived", "hid:/dev/hidraw0", "UMOCK0001"), ("left", "hid:/dev/hidraw0", "UMOCK0001"),
        ("arrived", "hid:/dev/hidraw0", "UMOCK0001")]
assert seen == want, seen
print("python watch: %s" % ", ".join(k for k, _, _ in seen))
print("1 passed, 0 failed")
sys.exit(0)
