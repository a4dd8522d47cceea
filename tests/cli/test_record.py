"""`cdm record` is kill-safe: a stop signal finishes a playable recording; it
never writes over its input or a non-regular file."""
import json
import os
import signal
import subprocess
import time

import pytest

from conftest import CLI, cdm


def record_then_signal(tmp_path, sig, uri="sim:", name="r.cdmrec", extra=()):
    out = tmp_path / name
    p = subprocess.Popen([CLI, "record", uri, str(out), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    # Wait for the first progress line: the device is open and recording.
    deadline = time.monotonic() + 30
    line = ""
    while "recorded" not in line and "jig position" not in line and time.monotonic() < deadline:
        line = p.stderr.readline()
        assert line or p.poll() is None, "record exited early"
    time.sleep(0.3)
    p.send_signal(sig)
    stdout, stderr = p.communicate(timeout=30)
    return p.returncode, stdout, stderr, out


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_signal_leaves_a_playable_recording(tmp_path, sig):
    rc, stdout, stderr, out = record_then_signal(tmp_path, sig)
    assert rc == 0, stderr
    assert out.is_file() and not (tmp_path / (out.name + ".tmp")).exists()
    n = int(stdout.split("wrote ", 1)[1].split(": ", 1)[1].split(" reports")[0])
    assert n > 0
    r = cdm("stream", "replay:" + str(out), "--json", "--rate", "50", "--seconds", "60")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout.splitlines()[-1])
    # Every recorded report plays back, and the replay reaches its end.
    assert summary["end_of_stream"] is True
    assert summary["reports"] == n


def test_jig_record_finishes_on_sigterm(tmp_path):
    uri = "sim:?motion=jig&jig_n=3&jig_heights=30,40&jig_samples=5"
    rc, _, stderr, out = record_then_signal(tmp_path, signal.SIGTERM, uri, "jig.csv", ["--jig"])
    # Stopped before the plan was complete, or completed first: either way
    # the CSV is in place with its header, and the stop is reported honestly.
    assert rc in (0, 1), stderr
    # t_s is there once a row is (a file stopped before any has the plain header).
    assert out.read_text().split("\n")[0] in ("point,x_ref,y_ref,z_ref,l1,l2,l3,l4",
                                              "point,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s")
    if rc == 1:
        assert "before the jig plan was complete" in stderr


def test_jig_options_contradicting_the_uri_are_usage(tmp_path):
    r = cdm("record", "sim:?motion=jig&jig_n=3", str(tmp_path / "j.csv"), "--jig", "--jig-n", "5")
    assert r.returncode == 2 and "jig_" in r.stderr
    r = cdm("record", "sim:", str(tmp_path / "j.csv"), "--jig", "--jig-heights", "30,x")
    assert r.returncode == 2 and "--jig-heights" in r.stderr


def test_never_writes_over_its_input(tmp_path):
    rec = tmp_path / "in.cdmrec"
    assert cdm("record", "sim:", str(rec), "--seconds", "0.2").returncode == 0
    before = rec.read_bytes()
    r = cdm("record", "replay:" + str(rec), str(rec))
    assert r.returncode == 2 and "input" in r.stderr
    assert rec.read_bytes() == before
    link = tmp_path / "link.cdmrec"
    os.symlink(rec, link)
    r = cdm("record", "replay:" + str(link), str(rec))
    assert r.returncode == 2 and rec.read_bytes() == before


def test_never_writes_over_a_non_regular_file(tmp_path):
    r = cdm("record", "sim:", "/dev/null", "--seconds", "0.2")
    assert r.returncode == 2 and "not a regular file" in r.stderr
    r = cdm("record", "sim:", str(tmp_path), "--seconds", "0.2")
    assert r.returncode == 2 and "not a regular file" in r.stderr


def _fsize_limit(limit):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        import resource
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.fixture
def small_tmpfs(tmp_path):
    """A 64 KiB tmpfs: a real full disk (ENOSPC). Needs root; skipped
    otherwise (the RLIMIT_FSIZE variant covers the same path with EFBIG)."""
    d = tmp_path / "full"
    d.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs (not root, or mount refused)")
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], capture_output=True)


OLD = b"the user's earlier recording, which a failed write must not replace\n"


def _expect_old_target_kept(r, out, cause):
    assert r.returncode == 1, r.stderr
    assert cause in r.stderr, r.stderr  # the real cause (not a stale errno)
    assert "not replaced" in r.stderr and str(out) + ".tmp" in r.stderr, r.stderr
    assert out.read_bytes() == OLD
    tmp = out.parent / (out.name + ".tmp")
    assert tmp.is_file() and tmp.stat().st_size > 12  # what was written before the error


# A file-size limit stands in for a full disk: the write fails with EFBIG
# as it would with ENOSPC, without needing a small filesystem.
@pytest.mark.parametrize("name", ["full.cdmrec", "full.csv", "full.mcap"])
def test_write_error_never_replaces_the_old_file(tmp_path, name):
    out = tmp_path / name
    out.write_bytes(OLD)
    r = subprocess.run([CLI, "record", "sim:?rate=1000", str(out), "--seconds", "5"],
                       preexec_fn=_fsize_limit(20000), capture_output=True, text=True, timeout=60)
    _expect_old_target_kept(r, out, os.strerror(27))  # EFBIG


@pytest.mark.parametrize("name", ["full.cdmrec", "full.csv", "full.mcap"])
def test_full_disk_never_replaces_the_old_file(small_tmpfs, tmp_path, name):
    out = small_tmpfs / name
    out.write_bytes(OLD)
    r = subprocess.run([CLI, "record", "sim:?rate=1000", str(out), "--seconds", "5"], capture_output=True,
                       text=True, timeout=60)
    _expect_old_target_kept(r, out, os.strerror(28))  # ENOSPC


def test_export_on_full_disk_never_replaces_the_old_file(small_tmpfs, tmp_path):
    src = tmp_path / "in.cdmrec"
    assert cdm("record", "sim:?rate=1000", str(src), "--seconds", "1").returncode == 0
    out = small_tmpfs / "out.csv"
    out.write_bytes(OLD)
    r = subprocess.run([CLI, "export", str(src), str(out)], capture_output=True, text=True, timeout=60)
    _expect_old_target_kept(r, out, os.strerror(28))


def test_jig_record_writes_acquisition_time(tmp_path):
    # The device's clock in a t_s column, non-decreasing in row order: what
    # drift over the session is measured against (docs/calibration.md).
    out = tmp_path / "jig.csv"
    r = cdm("record", "sim:?motion=jig&jig_n=3&jig_heights=30,40&jig_samples=5&realtime=0", str(out), "--jig")
    assert r.returncode == 0, r.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "point,x_ref,y_ref,z_ref,l1,l2,l3,l4,t_s"
    t = [float(l.split(",")[8]) for l in lines[1:]]
    assert len(t) == 3 * 3 * 2 * 5
    assert t[0] >= 0 and all(b >= a for a, b in zip(t, t[1:])) and t[-1] > t[0]
    # and the library reads it back
    r = cdm("calib", "fit", str(out), "--effects", "cable_offset", "--out", str(tmp_path / "c.json"))
    assert r.returncode == 0, r.stderr


def test_a_pot_at_its_rail_is_no_length(tmp_path):
    """A position beyond the pots' range (a 1 m hole on a 150 mm frame): the
    ADC sits at its ceiling, which measures no length. Its samples are left
    out and the position is named, never written as data; the reachable
    position is kept whole."""
    plan = tmp_path / "plan.csv"
    plan.write_text("x_ref,y_ref,z_ref,samples\n50,0,0,5\n50,1000,1000,5\n")
    out = tmp_path / "jig.csv"
    uri = f"sim:?motion=jig&jig_n=3&jig_pitch=1000&jig_heights=50&jig_samples=5&realtime=0&jig_plan={plan}"
    r = cdm("record", uri, str(out), "--jig", "--plan", str(plan), "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["positions"] == 1 and summary["of"] == 2 and summary["samples"] == 5
    assert summary["rail_samples"] == 5 and summary["rail_positions"] == [[50, 1000, 1000]]
    assert "a pot at its ADC's full scale (65535 counts)" in r.stderr
    rows = out.read_text().splitlines()[1:]
    assert len(rows) == 5 and all(r.split(",")[1:4] == ["50.0000", "0.0000", "0.0000"] for r in rows)
