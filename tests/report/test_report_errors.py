"""Bad input: exit code 2, the file named, nothing (partial) written."""
import json

import pytest

from conftest import check_page, run_report
import _synth


def _assert_rejected(r, path, *words):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert str(path) in r.stderr, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_malformed_json(tmp_path):
    bad = tmp_path / "broken diag.json"
    bad.write_text('{"tool": "cdm calib diagnose",\n "model": [}', encoding="utf-8")
    out = tmp_path / "r"
    r = run_report(bad, "--out", out)
    _assert_rejected(r, bad, "not valid JSON", "line 2")
    assert not (out / "index.html").exists()
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("text,why", [
    ("[1, 2, 3]", "top level is a JSON list"),
    ('"diagnosis"', "top level is a JSON str"),
    ('{"tool": "cdm calib fit", "model": []}', "cdm calib fit"),
    ('{"a_mm": 300, "b_mm": 250, "m_mm": 30}', "not a diagnosis"),
])
def test_not_a_diagnosis(tmp_path, text, why):
    bad = tmp_path / "device.json"
    bad.write_text(text, encoding="utf-8")
    r = run_report(bad, "--out", tmp_path / "r")
    _assert_rejected(r, bad, "not a diagnosis", why)


def test_missing_file(tmp_path):
    missing = tmp_path / "nope.json"
    r = run_report(missing, "--out", tmp_path / "r")
    _assert_rejected(r, missing, "cannot read")


def test_not_utf8(tmp_path):
    bad = tmp_path / "bin.json"
    bad.write_bytes(b"\xff\xfe\x00{")
    r = run_report(bad, "--out", tmp_path / "r")
    _assert_rejected(r, bad)


def test_bad_before_file_keeps_old_report(tmp_path):
    """A bad earlier run is named; the report already in DIR stays untouched."""
    good = _synth.write(tmp_path / "d.json", _synth.make_diag(n=5, heights=(40, 60)))
    out = tmp_path / "r"
    assert run_report(good, "--out", out).returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    bad = tmp_path / "before.json"
    bad.write_text("{\"tool\": \"cdm calib diagnose\", NaN", encoding="utf-8")
    r = run_report(bad, good, "--out", out)
    _assert_rejected(r, bad, "not valid JSON")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    check_page(out)


def test_usage_error_is_not_a_crash(tmp_path):
    r = run_report("--out", tmp_path / "r")  # no diagnosis given
    assert r.returncode == 2 and "usage" in r.stderr.lower()


def test_stale_figures_removed(tmp_path):
    out = tmp_path / "r"
    a = _synth.write(tmp_path / "a.json", _synth.make_diag(n=5, heights=(30, 70)))
    assert run_report(a, "--out", out).returncode == 0
    assert (out / "residual_map_h30.png").exists()
    (out / "notes.txt").write_text("the user's own file")
    b = _synth.write(tmp_path / "b.json", _synth.make_diag(n=5, heights=(45,)))
    assert run_report(b, "--out", out).returncode == 0
    assert not (out / "residual_map_h30.png").exists()
    assert (out / "residual_map_h45.png").exists()
    assert (out / "notes.txt").exists()  # not ours: left alone
    check_page(out)


def test_report_refuses_a_non_empty_directory_it_did_not_create(tmp_path):
    """`--report .` in a directory of the user's: refused, nothing touched,
    even files named like the report's figures."""
    out = tmp_path / "mine"
    out.mkdir()
    own = {"residual_map_h30.png": b"the user's picture", "error_summary.png": b"another", "notes.txt": b"x"}
    for name, data in own.items():
        (out / name).write_bytes(data)
    a = _synth.write(tmp_path / "a.json", _synth.make_diag(n=5, heights=(30, 70)))
    r = run_report(a, "--out", out)
    assert r.returncode == 2 and "not empty" in r.stderr and str(out) in r.stderr, r.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == own


def test_report_never_deletes_a_file_it_did_not_write(tmp_path):
    """In its own directory, a later report removes the figures an earlier
    report wrote and it does not redraw, never the user's files added since,
    whatever their names."""
    out = tmp_path / "r"
    a = _synth.write(tmp_path / "a.json", _synth.make_diag(n=5, heights=(30, 70)))
    assert run_report(a, "--out", out).returncode == 0
    (out / "residual_map_h99.png").write_bytes(b"the user's own figure")
    b = _synth.write(tmp_path / "b.json", _synth.make_diag(n=5, heights=(45,)))
    assert run_report(b, "--out", out).returncode == 0
    assert not (out / "residual_map_h30.png").exists()  # the earlier report's, not redrawn
    assert (out / "residual_map_h99.png").read_bytes() == b"the user's own figure"
    (out / "residual_map_h99.png").unlink()  # the page's own check counts every PNG
    check_page(out)


def test_report_writes_into_an_empty_directory(tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    a = _synth.write(tmp_path / "a.json", _synth.make_diag(n=5, heights=(40,)))
    assert run_report(a, "--out", out).returncode == 0
    check_page(out)


def test_self_check_catches_broken_output(tmp_path):
    """The checkers themselves must be able to fail."""
    from conftest import check_png
    a = _synth.write(tmp_path / "a.json", _synth.make_diag(n=5, heights=(40,)))
    out = tmp_path / "r"
    assert run_report(a, "--out", out).returncode == 0
    png = out / "residual_cut.png"
    data = png.read_bytes()
    png.write_bytes(data[: len(data) // 2])
    with pytest.raises(AssertionError):
        check_png(png)
    png.unlink()
    with pytest.raises(AssertionError):
        check_page(out)  # the page references a figure that is gone
    (out / "index.html").write_text('<img src="x.png"><script src="https://x"></script>')
    with pytest.raises(AssertionError):
        check_page(out)
    json.loads(open(a).read())  # the fixture itself is plain JSON (no NaN)


def test_out_is_a_file(tmp_path):
    good = _synth.write(tmp_path / "d.json", _synth.make_diag(n=3, heights=(40,)))
    out = tmp_path / "taken"
    out.write_text("a file, not a directory")
    r = run_report(good, "--out", out)
    assert r.returncode == 1 and str(out) in r.stderr and "Traceback" not in r.stderr


def test_balance_checker_catches_unclosed_tags():
    from conftest import check_balanced
    check_balanced("<html><body><table><tr><td>1</td></tr></table><img src=a.png></body></html>")
    with pytest.raises(AssertionError):
        check_balanced("<html><body><table><tr><td>1</td></table></body></html>")
