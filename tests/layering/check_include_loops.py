"""Fails when the sources of a folder given after src/ include each other in
a loop, or when any folder under src/ holds more than 20 files.

A unit is a header with its source (x.h and x.cpp); a unit depends on the
units whose headers any of its files includes. A loop (x.cpp includes y.h
while y.cpp or y.h includes x.h) means neither can be read, tested or moved
without the other: one concern split in two files, or a layer upside down.
Includes name their file from src/ ("calib/fit/fit.h" is src/calib/fit/fit.h)
or from the including file's folder.

Usage: check_include_loops.py SRC FOLDER... (the folders whose loops are
checked, relative to SRC: calib, where every file is one concern of one
layer; the facades elsewhere, the effects' list that every effect's
base.h is included through, device.cpp over its transports and
recording.cpp over its formats, are loops by this rule)."""
import pathlib
import re
import sys

MAX_FILES = 20
SUFFIXES = {".h", ".hpp", ".c", ".cpp"}

src = pathlib.Path(sys.argv[1]).resolve()
checked = [src / d for d in sys.argv[2:]]
include = re.compile(r'\s*#\s*include\s*"([^"]+)"')


def unit(path):
    return path.relative_to(src).with_suffix("").as_posix()


deps = {}
for f in sorted(src.rglob("*")):
    if f.suffix not in SUFFIXES or not f.is_file():
        continue
    u = unit(f)
    deps.setdefault(u, set())
    for line in f.read_text(errors="replace").splitlines():
        m = include.match(line)
        if not m:
            continue
        for base in (src, f.parent):
            target = (base / m.group(1)).resolve()
            if target.is_file() and target.is_relative_to(src):
                if unit(target) != u:
                    deps[u].add(unit(target))
                break

# Tarjan's strongly connected components: each of more than one unit is a loop.
index, low, stack, on_stack, loops = {}, {}, [], set(), []


def visit(v):
    index[v] = low[v] = len(index)
    stack.append(v)
    on_stack.add(v)
    for w in sorted(deps.get(v, ())):
        if w not in index:
            visit(w)
            low[v] = min(low[v], low[w])
        elif w in on_stack:
            low[v] = min(low[v], index[w])
    if low[v] == index[v]:
        comp = []
        while True:
            w = stack.pop()
            on_stack.discard(w)
            comp.append(w)
            if w == v:
                break
        if len(comp) > 1 and any((src / c).is_relative_to(d) for c in comp for d in checked):
            loops.append(sorted(comp))


sys.setrecursionlimit(10000)
for v in sorted(deps):
    if v not in index:
        visit(v)

bad = [f"include loop: {' <-> '.join(c)}" for c in loops]
for d in sorted(p for p in [src, *src.rglob("*")] if p.is_dir()):
    n = sum(1 for f in d.iterdir() if f.is_file())
    if n > MAX_FILES:
        bad.append(f"{d.relative_to(src.parent)}: {n} files (at most {MAX_FILES})")
print("\n".join(bad) if bad else
      f"no include loop under {', '.join(sys.argv[2:])} and no folder over {MAX_FILES} files under {src}")
sys.exit(1 if bad else 0)
