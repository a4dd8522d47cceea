"""Helpers for the report tests: run the tool, check PNGs and the page."""
import os
import re
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
PYROOT = ROOT / "bindings" / "python"
# CDM_REPORT_SCRIPT: test another copy of the tool (e.g. a deliberately broken one);
# its package is the report/ directory beside it.
SCRIPT = Path(os.environ.get("CDM_REPORT_SCRIPT", PYROOT / "cdm" / "report.py"))
sys.path.insert(0, str(HERE))


def report_package():
    """The report package beside SCRIPT, imported as SCRIPT imports it (under the name
    cdm_report, without cdm/__init__.py), with its submodules loaded."""
    if "cdm_report" not in sys.modules:
        import importlib.util
        pkg = SCRIPT.parent / "report"
        spec = importlib.util.spec_from_file_location(
            "cdm_report", pkg / "__init__.py", submodule_search_locations=[str(pkg)])
        m = importlib.util.module_from_spec(spec)
        sys.modules["cdm_report"] = m
        spec.loader.exec_module(m)
    import cdm_report.drawing  # noqa: F401
    import cdm_report.figures  # noqa: F401
    import cdm_report.page  # noqa: F401
    import cdm_report.sections.variables  # noqa: F401
    return sys.modules["cdm_report"]


def run_report(*args, module=False):
    """Run the tool as a script (default) or as `-m cdm.report`; CompletedProcess."""
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONDONTWRITEBYTECODE="1")
    if module:
        env["PYTHONPATH"] = os.pathsep.join([str(PYROOT)] + [p for p in
                                            env.get("PYTHONPATH", "").split(os.pathsep) if p])
        cmd = [sys.executable, "-m", "cdm.report"]
    else:
        cmd = [sys.executable, str(SCRIPT)]
    return subprocess.run(cmd + [str(a) for a in args], capture_output=True, text=True,
                          env=env, timeout=300)


def check_png(path):
    """Raise AssertionError unless path is a complete, decodable, non-blank PNG."""
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path}: no PNG signature"
    pos, chunks, idat = 8, [], b""
    while pos < len(data):
        assert pos + 8 <= len(data), f"{path}: truncated chunk header"
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        crc = data[pos + 8 + n:pos + 12 + n]
        assert len(body) == n and len(crc) == 4, f"{path}: truncated {kind!r} chunk"
        assert struct.unpack(">I", crc)[0] == zlib.crc32(kind + body), f"{path}: bad CRC"
        chunks.append(kind)
        if kind == b"IDAT":
            idat += body
        pos += 12 + n
    assert chunks[0] == b"IHDR" and chunks[-1] == b"IEND", f"{path}: chunks {chunks}"
    w, h = struct.unpack(">II", data[16:24])
    assert w >= 200 and h >= 150, f"{path}: only {w}x{h} pixels"
    zlib.decompress(idat)  # raises on a corrupt stream
    import matplotlib.image as mpimg
    img = mpimg.imread(str(path))
    assert img.shape[0] == h and img.shape[1] == w
    assert float(img[..., :3].std()) > 0.01, f"{path}: a flat image"
    return w, h


def image_refs(html):
    return re.findall(r'<img[^>]*\ssrc="([^"]+)"', html)


def check_page(outdir):
    """index.html references every PNG in outdir, each reference exists, nothing external."""
    outdir = Path(outdir)
    html = (outdir / "index.html").read_text(encoding="utf-8")
    refs = image_refs(html)
    pngs = sorted(p.name for p in outdir.glob("*.png"))
    assert sorted(set(refs)) == pngs, f"page refs {sorted(refs)} != files {pngs}"
    for r in refs:
        assert "/" not in r and not r.startswith("."), f"not a plain relative path: {r}"
    low = html.lower()
    for bad in ("<script", "http://", "https://", "<link", "@import", "url("):
        assert bad not in low, f"page uses an external resource or script: {bad}"
    assert not [p for p in outdir.iterdir() if p.is_dir()], "a temporary directory was left"
    check_balanced(html)
    return html


def check_balanced(html):
    """Every non-void element is closed, in order."""
    from html.parser import HTMLParser
    void = {"meta", "img", "br", "hr", "link", "input"}

    class P(HTMLParser):
        def __init__(self):
            super().__init__()
            self.stack = []

        def handle_starttag(self, tag, attrs):
            if tag not in void:
                self.stack.append(tag)

        def handle_endtag(self, tag):
            assert self.stack and self.stack[-1] == tag, f"</{tag}> closes {self.stack[-3:]}"
            self.stack.pop()

    p = P()
    p.feed(html)
    p.close()
    assert p.stack == [], f"unclosed: {p.stack}"


@pytest.fixture
def synth():
    import _synth
    return _synth
