"""MCAP recordings (docs/recording.md): `cdm record sim: FILE.mcap` writes a
file the `mcap` package (PyPI, the format's own reader) reads with every CRC
checked; `replay:FILE.mcap` plays it back to the very poses recorded; `cdm
export` converts both ways without losing a byte; hostile or truncated files
get a clear error or a stated loss, never a crash."""
import csv
import io
import json
import signal
import struct
import subprocess
import time

import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.records import Footer

from conftest import CLI, cdm

TOPICS = {"/cdm/report", "/cdm/pose", "/cdm/state"}
# Flags a replay may set differently from the live session: it runs at its
# own pace (STALE) and has an end (END_OF_STREAM, DISCONNECTED after it).
PACE_FLAGS = 1 | 2 | 16


def record(tmp_path, name, seconds="0.4"):
    out = tmp_path / name
    r = cdm("record", "sim:", str(out), "--seconds", seconds)
    assert r.returncode == 0, r.stderr
    n = int(r.stdout.split("wrote ", 1)[1].split(": ", 1)[1].split(" reports")[0])
    assert n > 0
    return out, n


def read_mcap(path):
    """Every record framed and every CRC checked (chunks, data section), then
    the messages through the indexed reader, as Foxglove would seek."""
    with open(path, "rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    assert isinstance(records[-1], Footer)
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        msgs = list(reader.iter_messages(log_time_order=False))
        metadata = list(reader.iter_metadata())
    return summary, msgs, metadata


def by_topic(msgs):
    out = {}
    for schema, channel, message in msgs:
        out.setdefault(channel.topic, []).append((schema, channel, message))
    return out


def cdmrec_records(path):
    """The replay format (docs/protocol.md): header, info report, records."""
    b = path.read_bytes()
    assert b[:8] == b"CDMRPLAY"
    info_len = struct.unpack_from("<H", b, 10)[0]
    info = b[12:12 + info_len]
    off, recs = 12 + info_len, []
    while off < len(b):
        t, n = struct.unpack_from("<QH", b, off)
        recs.append((t, b[off + 10:off + 10 + n]))
        off += 10 + n
    return info, recs


def test_record_mcap_is_read_by_the_mcap_package(tmp_path):
    out, n = record(tmp_path, "r.mcap")
    summary, msgs, metadata = read_mcap(out)
    topics = by_topic(msgs)
    assert set(topics) == TOPICS
    # One report, one pose, one state per report, all counted in the summary.
    assert all(len(v) == n for v in topics.values()), {k: len(v) for k, v in topics.items()}
    counts = summary.statistics.channel_message_counts
    assert {summary.channels[c].topic: k for c, k in counts.items()} == {t: n for t in TOPICS}
    assert summary.statistics.message_count == 3 * n
    assert summary.chunk_indexes, "no chunk index: readers could not seek"
    # Schemas: the raw report's layout by name, the poses as JSON Schema.
    schema = {t: v[0][0] for t, v in topics.items()}
    chan = {t: v[0][1] for t, v in topics.items()}
    assert (schema["/cdm/report"].name, schema["/cdm/report"].encoding) == ("cdm.report.v1", "")
    assert chan["/cdm/report"].message_encoding == "cdm.report.v1"
    assert (schema["/cdm/pose"].name, schema["/cdm/pose"].encoding) == ("foxglove.PoseInFrame", "jsonschema")
    assert (schema["/cdm/state"].name, schema["/cdm/state"].encoding) == ("cdm.State", "jsonschema")
    for t in ("/cdm/pose", "/cdm/state"):
        assert chan[t].message_encoding == "json"
        assert json.loads(schema[t].data)["title"] == schema[t].name
    # The device-info report, for replay, and who recorded it.
    dev = [m for m in metadata if m.name == "cdm.device"]
    assert len(dev) == 1
    info = bytes.fromhex(dev[0].metadata["info_report_hex"])
    assert info[0] == 0x02 and dev[0].metadata["serial"] == "CDMSIM0001"

    reports = topics["/cdm/report"]
    poses = [json.loads(m.data) for _, _, m in topics["/cdm/pose"]]
    states = [json.loads(m.data) for _, _, m in topics["/cdm/state"]]
    for (_, _, rep), (_, _, pm), p, s in zip(reports, topics["/cdm/pose"], poses, states):
        assert rep.data[0] == 0x01 and len(rep.data) == 64  # input report 0x01, report ID first
        assert rep.log_time == pm.log_time == s["timestamp"]["sec"] * 10**9 + s["timestamp"]["nsec"]
        # metres from mm: one multiplication by 1e-3, so one rounding (1 ulp).
        for k in "xyz":
            assert p["pose"]["position"][k] * 1e3 == pytest.approx(s["position_mm"][k], rel=1e-15, abs=1e-12)
            assert p["pose"]["orientation"][k] == s["orientation"][k]
        assert p["pose"]["orientation"]["w"] == s["orientation"]["w"]
        # A unit quaternion from the IMU's Q14 words, normalised by libcdm.
        assert sum(v * v for v in s["orientation"].values()) == pytest.approx(1.0, abs=1e-9)
        # The simulated master moves inside its workspace (a few hundred mm).
        assert all(abs(s["position_mm"][k]) < 1000 for k in "xyz")
        assert p["frame_id"] == "cdm"
    seqs = [s["sequence"] for s in states]
    assert seqs == sorted(seqs) and len(set(seqs)) == n
    times = [m.log_time for _, _, m in reports]
    assert times == sorted(times)


def test_replay_of_mcap_gives_the_recorded_poses(tmp_path):
    out, n = record(tmp_path, "r.mcap")
    _, msgs, _ = read_mcap(out)
    states = [json.loads(m.data) for _, c, m in msgs if c.topic == "/cdm/state"]
    # The same reports through replay: (the library's parser, conversion and
    # filters again), exported as CSV: the same numbers, bit for bit.
    csv_out = tmp_path / "replayed.csv"
    r = cdm("export", str(out), str(csv_out))
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(io.StringIO(csv_out.read_text())))
    assert len(rows) == n
    for s, row in zip(states, rows):
        assert int(row["host_time_ns"]) == s["timestamp"]["sec"] * 10**9 + s["timestamp"]["nsec"]
        assert int(row["sequence"]) == s["sequence"] and int(row["device_time_us"]) == s["device_time_us"]
        assert [float(row[k + "_mm"]) for k in "xyz"] == [s["position_mm"][k] for k in "xyz"]
        assert [float(row["q" + k]) for k in "wxyz"] == [s["orientation"][k] for k in "wxyz"]
        assert [float(row["v" + k + "_mm_s"]) for k in "xyz"] == [s["velocity_mm_s"][k] for k in "xyz"]
        assert float(row["grip_rad"]) == s["grip_rad"] and int(row["buttons"]) == s["buttons"]
        assert int(row["flags"]) & ~PACE_FLAGS == s["flags"] & ~PACE_FLAGS
        assert int(row["dropped"]) == s["dropped"]
    # And through `cdm stream`, the way a user plays it: every report, to the end.
    r = cdm("stream", "replay:" + str(out), "--json", "--rate", "50", "--seconds", "60")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout.splitlines()[-1])
    assert summary["end_of_stream"] is True and summary["reports"] == n


def test_export_both_ways_keeps_every_byte_and_time(tmp_path):
    rec, n = record(tmp_path, "r.cdmrec")
    info, recs = cdmrec_records(rec)
    assert len(recs) == n
    m = tmp_path / "r.mcap"
    r = cdm("export", str(rec), str(m))
    assert r.returncode == 0, r.stderr
    _, msgs, metadata = read_mcap(m)
    reports = [msg for _, c, msg in msgs if c.topic == "/cdm/report"]
    # The recorded receipt times, not the export's: the replay hands them on.
    assert [(x.log_time, x.data) for x in reports] == recs
    assert bytes.fromhex(next(md for md in metadata if md.name == "cdm.device").metadata["info_report_hex"]) == info
    assert sum(1 for _, c, _ in msgs if c.topic == "/cdm/state") == n
    back = tmp_path / "back.cdmrec"
    r = cdm("export", str(m), str(back))
    assert r.returncode == 0, r.stderr
    assert back.read_bytes() == rec.read_bytes()
    # Exports never write over their input, nor a file that is not regular.
    r = cdm("export", str(m), str(m))
    assert r.returncode == 2 and "input" in r.stderr


def test_sigint_finishes_the_mcap(tmp_path):
    out = tmp_path / "s.mcap"
    p = subprocess.Popen([CLI, "record", "sim:", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    line = ""
    while "recorded" not in line and time.monotonic() < deadline:
        line = p.stderr.readline()
        assert line or p.poll() is None, "record exited early"
    time.sleep(0.3)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=30)
    assert p.returncode == 0, stderr
    n = int(stdout.split("wrote ", 1)[1].split(": ", 1)[1].split(" reports")[0])
    summary, msgs, _ = read_mcap(out)  # footer, summary and CRCs all there
    assert summary.statistics.message_count == 3 * n and n > 0
    assert not (tmp_path / "s.mcap.tmp").exists()


def replay_error(path):
    r = cdm("export", str(path), str(path.with_suffix(".out.csv")))
    return r.returncode, r.stderr


def test_hostile_and_truncated_mcap(tmp_path):
    good, n = record(tmp_path, "g.mcap")
    data = good.read_bytes()

    # Cut inside the header: refused, naming the byte.
    cut = tmp_path / "cut_header.mcap"
    cut.write_bytes(data[:12])
    rc, err = replay_error(cut)
    assert rc == 1 and "byte 8" in err and "Header" in err

    # Cut in the middle (a recorder killed): the complete chunks play, and
    # what was lost is said.
    half = tmp_path / "half.mcap"
    half.write_bytes(data[:len(data) // 2])
    out = tmp_path / "half.csv"
    r = cdm("export", str(half), str(out))
    assert r.returncode == 0, r.stderr
    assert "trailing bytes dropped" in r.stderr
    rows = out.read_text().splitlines()[1:]
    assert 0 < len(rows) < n

    # A flipped byte inside a chunk: its CRC says so.
    bad = bytearray(data)
    bad[len(data) // 3] ^= 0xFF
    (tmp_path / "flip.mcap").write_bytes(bytes(bad))
    rc, err = replay_error(tmp_path / "flip.mcap")
    assert rc == 1 and "byte " in err and ("CRC" in err or "runs past" in err), err

    # A record announcing more than the file holds, mid-file.
    huge = bytearray(data[:8]) + bytes([0x01]) + struct.pack("<Q", 2**63) + bytes(40)
    (tmp_path / "huge.mcap").write_bytes(bytes(huge))
    rc, err = replay_error(tmp_path / "huge.mcap")
    assert rc == 1 and "byte 8" in err

    # Not MCAP at all, and another major version.
    (tmp_path / "junk.mcap").write_bytes(b"\x89MCAQ0\r\n" + bytes(100))
    rc, err = replay_error(tmp_path / "junk.mcap")
    assert rc == 1 and "byte 0" in err
    (tmp_path / "v1.mcap").write_bytes(b"\x89MCAP1\r\n" + bytes(100))
    rc, err = replay_error(tmp_path / "v1.mcap")
    assert rc == 1 and "version" in err

    # Valid MCAP from another tool: compressed (the mcap package's default)
    # and without cdm's device metadata: both refused by name.
    from mcap.writer import Writer, CompressionType
    for comp, expect in ((CompressionType.ZSTD, "zstd"), (CompressionType.NONE, "cdm.device")):
        path = tmp_path / f"other_{comp.name}.mcap"
        with open(path, "wb") as f:
            w = Writer(f, compression=comp)
            w.start()
            sid = w.register_schema("x", "jsonschema", b"{}")
            cid = w.register_channel("/x", "json", sid)
            w.add_message(cid, log_time=1, publish_time=1, data=b"{}")
            w.finish()
        rc, err = replay_error(path)
        assert rc == 1 and expect in err, err


def test_full_disk_keeps_whole_chunks_that_replay(tmp_path):
    # A file-size limit stands in for a full disk (EFBIG as ENOSPC would):
    # the chunk that does not fit is cut off again, the chunks before it
    # stay in the temporary (the target is never replaced by a partial
    # file), and replay: plays them, saying the footer is missing.
    import os
    import resource

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (300000, 300000))

    out = tmp_path / "full.mcap"
    r = subprocess.run([CLI, "record", "sim:", str(out), "--seconds", "5"], preexec_fn=limit, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 1
    assert os.strerror(27) in r.stderr and "is kept in " + str(out) + ".tmp" in r.stderr
    assert not out.exists()
    kept = tmp_path / "kept.mcap"
    os.rename(str(out) + ".tmp", kept)
    csv_out = tmp_path / "full.csv"
    r = cdm("export", str(kept), str(csv_out))
    assert r.returncode == 0, r.stderr
    assert "without its footer" in r.stderr
    assert len(csv_out.read_text().splitlines()) > 100  # two chunks' worth of reports, not an empty file
