"""Fails when a source under src/ includes a file through "../" that lies in
another module's folder: the include paths enforce the layering, and this is
the one way round them the compiler cannot see."""
import pathlib
import re
import sys

src = pathlib.Path(sys.argv[1]).resolve()
bad = []
for f in sorted(src.rglob("*")):
    if f.suffix not in {".h", ".hpp", ".c", ".cpp"}:
        continue
    module = f.relative_to(src).parts[0]
    for n, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
        m = re.match(r'\s*#\s*include\s*"([^"]+)"', line)
        if not m or ".." not in m.group(1):
            continue
        target = (f.parent / m.group(1)).resolve()
        try:
            target_module = target.relative_to(src).parts[0]
        except ValueError:
            target_module = None
        if target_module != module:
            bad.append(f"{f.relative_to(src.parent)}:{n}: {m.group(1)} leaves module {module}")
print("\n".join(bad) if bad else f"no relative include leaves its module under {src}")
sys.exit(1 if bad else 0)
