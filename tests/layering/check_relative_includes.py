"""Fails when a source under src/ includes a file through "../" that lies in
another module's folder: the include paths enforce the layering, and this is
the one way round them the compiler cannot see. A module's folder is the
nearest one up whose CMakeLists.txt calls cdm_module (src/calib/fit is one,
src/device/sim belongs to src/device)."""
import pathlib
import re
import sys

src = pathlib.Path(sys.argv[1]).resolve()


def module_of(path):
    for d in [path, *path.parents] if path.is_dir() else path.parents:
        if d == src or src not in d.parents:
            return None
        cm = d / "CMakeLists.txt"
        if cm.is_file() and "cdm_module(" in cm.read_text(errors="replace"):
            return d.relative_to(src).as_posix()
    return None


bad = []
for f in sorted(src.rglob("*")):
    if f.suffix not in {".h", ".hpp", ".c", ".cpp"}:
        continue
    module = module_of(f)
    for n, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
        m = re.match(r'\s*#\s*include\s*"([^"]+)"', line)
        if not m or ".." not in m.group(1):
            continue
        target = (f.parent / m.group(1)).resolve()
        target_module = module_of(target)
        if target_module != module:
            bad.append(f"{f.relative_to(src.parent)}:{n}: {m.group(1)} leaves module {module}")
print("\n".join(bad) if bad else f"no relative include leaves its module under {src}")
sys.exit(1 if bad else 0)
