"""MCAP recordings (docs/recording.md): `cdm record sim: FILE.mcap` writes a
file the `mcap` package (PyPI, the format's own reader) reads with every CRC
checked and whose ROS 2 messages (CDR) `mcap-ros2-support` decodes;
`replay:FILE.mcap` plays it back to the very poses recorded, and plays what
the `mcap` package writes with zstd or lz4 chunks; `cdm export` converts both
ways without losing a byte; hostile or truncated files (compressed ones too)
get a clear error or a stated loss, never a crash."""
import csv
import io
import json
import os
import signal
import struct
import subprocess
import time

import pytest
from mcap.reader import make_reader
from mcap.records import Footer
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from mcap_ros2.decoder import DecoderFactory

from conftest import CLI, cdm

SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

TOPICS = {"/cdm/report", "/cdm/pose", "/cdm/state"}
# Flags a replay may set differently from the live session: it runs at its
# own pace (STALE) and has an end (END_OF_STREAM, DISCONNECTED after it).
PACE_FLAGS = 1 | 2 | 16


def record(tmp_path, name, seconds="0.4", *extra):
    out = tmp_path / name
    r = cdm("record", "sim:", str(out), "--seconds", seconds, *extra)
    assert r.returncode == 0, r.stderr
    n = int(r.stdout.split("wrote ", 1)[1].split(": ", 1)[1].split(" reports")[0])
    assert n > 0
    return out, n


def read_mcap(path):
    """Every record framed and every CRC checked (chunks, data section), then
    the messages through the indexed reader, as Foxglove would seek, the
    CDR ones decoded from the schemas in the file (mcap-ros2-support)."""
    with open(path, "rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    assert isinstance(records[-1], Footer)
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        msgs = list(reader.iter_messages(log_time_order=False))
        metadata = list(reader.iter_metadata())
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        decoded = {(d.channel.topic, d.message.sequence): d.decoded_message
                   for d in reader.iter_decoded_messages(topics=["/cdm/pose", "/cdm/state"], log_time_order=False)}
    return summary, msgs, metadata, decoded


def clock_offset(metadata):
    return int(next(m for m in metadata if m.name == "cdm.device").metadata["clock_offset_ns"])


def stamp(msg):
    return msg.sec * 10**9 + msg.nanosec


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
    t0 = time.time_ns()
    out, n = record(tmp_path, "r.mcap")
    t1 = time.time_ns()
    summary, msgs, metadata, decoded = read_mcap(out)
    topics = by_topic(msgs)
    assert set(topics) == TOPICS
    # One report and one pose per report; states every 10 ms of device time
    # (and on events): all counted in the summary.
    m = len(topics["/cdm/state"])
    assert len(topics["/cdm/report"]) == len(topics["/cdm/pose"]) == n and n // 20 < m < n // 5, (n, m)
    counts = summary.statistics.channel_message_counts
    assert {summary.channels[c].topic: k for c, k in counts.items()} == {"/cdm/report": n, "/cdm/pose": n,
                                                                          "/cdm/state": m}
    assert summary.statistics.message_count == 2 * n + m
    assert summary.chunk_indexes, "no chunk index: readers could not seek"
    # zstd by default, and it does compress.
    assert {ci.compression for ci in summary.chunk_indexes} == {"zstd"}
    assert sum(ci.compressed_size for ci in summary.chunk_indexes) < \
        sum(ci.uncompressed_size for ci in summary.chunk_indexes) / 2
    # Schemas: the raw report's layout by name, the poses as ROS 2 messages.
    schema = {t: v[0][0] for t, v in topics.items()}
    chan = {t: v[0][1] for t, v in topics.items()}
    assert (schema["/cdm/report"].name, schema["/cdm/report"].encoding) == ("cdm.report.v1", "")
    assert chan["/cdm/report"].message_encoding == "cdm.report.v1"
    assert (schema["/cdm/pose"].name, schema["/cdm/pose"].encoding) == ("geometry_msgs/msg/PoseStamped", "ros2msg")
    assert (schema["/cdm/state"].name, schema["/cdm/state"].encoding) == ("cdm_msgs/msg/State", "ros2msg")
    for t in ("/cdm/pose", "/cdm/state"):
        assert chan[t].message_encoding == "cdr"
    # The state's definition is the ROS 2 package's State.msg, then its dependencies.
    state_msg = open(os.path.join(SRC, "examples", "ros2", "cdm_msgs", "msg", "State.msg")).read()
    assert schema["/cdm/state"].data.decode().startswith(state_msg + "=" * 80 + "\n")
    # The device-info report, for replay, and who recorded it.
    dev = [m for m in metadata if m.name == "cdm.device"]
    assert len(dev) == 1
    info = bytes.fromhex(dev[0].metadata["info_report_hex"])
    assert info[0] == 0x02 and dev[0].metadata["serial"] == "CDMSIM0001"

    reports = topics["/cdm/report"]
    # Log times are wall-clock (ns since the epoch) during the recording.
    times = [m.log_time for _, _, m in reports]
    assert times == sorted(times) and t0 <= times[0] and times[-1] <= t1, (t0, times[0], times[-1], t1)
    by_time = {}
    for (_, _, rep), (_, _, pm) in zip(reports, topics["/cdm/pose"]):
        p = decoded[("/cdm/pose", pm.sequence)]
        assert rep.data[0] == 0x01 and len(rep.data) == 64  # input report 0x01, report ID first
        assert rep.log_time == pm.log_time == stamp(p.header.stamp)
        by_time[rep.log_time] = rep
        assert p.header.frame_id == "cdm"
        q = p.pose.orientation
        # A unit quaternion from the IMU's Q14 words, normalised by libcdm.
        assert q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w == pytest.approx(1.0, abs=1e-9)
        # The simulated master moves inside its workspace (a few hundred mm), in metres.
        assert all(abs(v) < 1.0 for v in (p.pose.position.x, p.pose.position.y, p.pose.position.z))
    states = []
    for _, _, sm in topics["/cdm/state"]:
        s = decoded[("/cdm/state", sm.sequence)]
        rep = by_time[sm.log_time]  # a state belongs to a report, stamped as it
        assert sm.log_time == stamp(s.stamp)
        # The device's own clock and counter travel in the state; the report holds them too.
        assert s.sequence == struct.unpack_from("<I", rep.data, 4)[0]
        assert s.device_time_us == struct.unpack_from("<Q", rep.data, 8)[0]
        assert 0 <= s.buttons < 8 and -0.05 < s.grip_rad < 0.65
        states.append(s)
    seqs = [s.sequence for s in states]
    assert seqs == sorted(seqs) and len(set(seqs)) == m
    # Every 10 ms of device time: no sooner unless buttons, flags or dropped
    # changed, no later than the first report past 10 ms.
    dev_t = [struct.unpack_from("<Q", rep.data, 8)[0] for _, _, rep in reports]
    report_gap = max(b - a for a, b in zip(dev_t, dev_t[1:]))
    for a, b in zip(states, states[1:]):
        event = (a.buttons, a.flags, a.dropped) != (b.buttons, b.flags, b.dropped)
        gap = b.device_time_us - a.device_time_us
        assert (gap >= 10000 or event) and gap < 10000 + report_gap, (a, b, report_gap)


def test_replay_of_mcap_gives_the_recorded_poses(tmp_path):
    out, n = record(tmp_path, "r.mcap")
    _, msgs, metadata, decoded = read_mcap(out)
    offset = clock_offset(metadata)
    poses = [decoded[("/cdm/pose", m.sequence)] for _, c, m in msgs if c.topic == "/cdm/pose"]
    states = {s.sequence: s for s in (decoded[("/cdm/state", m.sequence)] for _, c, m in msgs
                                      if c.topic == "/cdm/state")}
    # The same reports through replay: (the library's parser, conversion and
    # filters again), exported as CSV: the same numbers.
    csv_out = tmp_path / "replayed.csv"
    r = cdm("export", str(out), str(csv_out))
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(io.StringIO(csv_out.read_text())))
    assert len(rows) == n
    for p, row in zip(poses, rows):
        # The replay's host times are the recording's CLOCK_MONOTONIC ones.
        assert int(row["host_time_ns"]) == stamp(p.header.stamp) - offset
        # metres = mm * 1e-3, one rounding: back in mm within 1 ulp of a
        # number below 1000 mm (~1.1e-13 mm).
        pos = p.pose.position
        for k, v in zip("xyz", (pos.x, pos.y, pos.z)):
            assert v * 1e3 == pytest.approx(float(row[k + "_mm"]), rel=1e-15, abs=1e-12)
        q = p.pose.orientation
        assert [float(row["q" + k]) for k in "wxyz"] == [q.w, q.x, q.y, q.z]
        s = states.get(int(row["sequence"]))
        if s is None:
            continue
        assert int(row["device_time_us"]) == s.device_time_us and stamp(s.stamp) == stamp(p.header.stamp)
        v = s.velocity_mm_s
        assert [float(row["v" + k + "_mm_s"]) for k in "xyz"] == [v.x, v.y, v.z]
        assert float(row["grip_rad"]) == s.grip_rad and int(row["buttons"]) == s.buttons
        assert int(row["flags"]) & ~PACE_FLAGS == s.flags & ~PACE_FLAGS
        assert int(row["dropped"]) == s.dropped
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
    _, msgs, metadata, _ = read_mcap(m)
    reports = [msg for _, c, msg in msgs if c.topic == "/cdm/report"]
    # The recorded receipt times, not the export's: the replay hands them on,
    # shifted to wall-clock time by the offset the file states.
    offset = clock_offset(metadata)
    assert [(x.log_time - offset, x.data) for x in reports] == recs
    assert bytes.fromhex(next(md for md in metadata if md.name == "cdm.device").metadata["info_report_hex"]) == info
    assert sum(1 for _, c, _ in msgs if c.topic == "/cdm/pose") == n
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
    summary, msgs, _, _ = read_mcap(out)  # footer, summary and CRCs all there
    assert sum(1 for _, c, _ in msgs if c.topic == "/cdm/report") == n > 0
    assert not (tmp_path / "s.mcap.tmp").exists()


def replay_error(path):
    r = cdm("export", str(path), str(path.with_suffix(".out.csv")))
    return r.returncode, r.stderr


def test_hostile_and_truncated_mcap(tmp_path):
    # 3 s: several chunks (one holds about 1.3 s of compressed recording).
    good, n = record(tmp_path, "g.mcap", "3")
    data = good.read_bytes()
    with open(good, "rb") as f:
        assert len(make_reader(f).get_summary().chunk_indexes) >= 2

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

    # A flipped byte inside a compressed chunk: zstd's frame or the CRC of
    # the records says so.
    bad = bytearray(data)
    bad[len(data) // 3] ^= 0xFF
    (tmp_path / "flip.mcap").write_bytes(bytes(bad))
    rc, err = replay_error(tmp_path / "flip.mcap")
    assert rc == 1 and "byte " in err and ("CRC" in err or "runs past" in err or "zstd" in err), err

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

    # Valid MCAP from another tool, without cdm's device metadata: refused
    # by name, compressed or not.
    for comp, expect in ((CompressionType.ZSTD, "cdm.device"), (CompressionType.NONE, "cdm.device")):
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


def python_written_mcap(path, info, recs, compression, chunk_size=4096):
    """cdm's layout (docs/recording.md) written by the `mcap` package: the
    cdm.device metadata and the /cdm/report channel, chunks compressed as
    asked, several of them (chunk_size)."""
    with open(path, "wb") as f:
        w = Writer(f, compression=compression, chunk_size=chunk_size)
        w.start(profile="", library="mcap python")
        sid = w.register_schema("cdm.report.v1", "", b"")
        cid = w.register_channel("/cdm/report", "cdm.report.v1", sid)
        w.add_metadata("cdm.device", {"info_report_hex": info.hex()})
        for t, data in recs:
            w.add_message(cid, log_time=t, publish_time=t, data=data)
        w.finish()


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE])
def test_mcap_written_by_the_mcap_package_replays(tmp_path, compression):
    """Files the format's own Python writer makes, zstd, lz4 or uncompressed
    chunks: replay: plays every report at its log time (no clock_offset_ns
    there: the log time is the host time), so the export back to the
    replay format is the recording it came from, byte for byte."""
    rec, n = record(tmp_path, "r.cdmrec")
    info, recs = cdmrec_records(rec)
    m = tmp_path / ("py_%s.mcap" % compression.name)
    python_written_mcap(m, info, recs, compression)
    with open(m, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) > 1 and {c.compression for c in chunks} == {{"ZSTD": "zstd", "LZ4": "lz4", "NONE": ""}[
        compression.name]}
    back = tmp_path / "back.cdmrec"
    r = cdm("export", str(m), str(back))
    assert r.returncode == 0, r.stderr
    assert back.read_bytes() == rec.read_bytes()


@pytest.mark.parametrize("compression", ["lz4", "none", "zstd"])
def test_record_compression_option(tmp_path, compression):
    out, n = record(tmp_path, "c.mcap", "0.3", "--compression", compression)
    summary, msgs, _, decoded = read_mcap(out)
    assert {ci.compression for ci in summary.chunk_indexes} == {"" if compression == "none" else compression}
    assert sum(1 for _, c, _ in msgs if c.topic == "/cdm/report") == n
    assert len(decoded) == sum(1 for _, c, _ in msgs if c.topic != "/cdm/report") > n
    csv_out = tmp_path / "c.csv"
    r = cdm("export", str(out), str(csv_out))
    assert r.returncode == 0, r.stderr
    assert len(csv_out.read_text().splitlines()) == n + 1
    # Only MCAP has chunks; a compression it does not know is a usage error too.
    r = cdm("record", "sim:", str(tmp_path / "x.cdmrec"), "--seconds", "0.1", "--compression", compression)
    assert r.returncode == 2 and "--compression" in r.stderr, r.stderr
    r = cdm("record", "sim:", str(tmp_path / "y.mcap"), "--seconds", "0.1", "--compression", "gzip")
    assert r.returncode == 2 and "gzip" in r.stderr, r.stderr


def mcap_record(op, content):
    return bytes([op]) + struct.pack("<Q", len(content)) + content


def mcap_str(s):
    return struct.pack("<I", len(s)) + s


def chunk_file(records, compression, usize=None, crc=None, packed=None):
    """The magic, a Header, then one Chunk of `records` compressed as named
    (`usize`, `crc`, `packed`: what the chunk announces and holds, if not
    the truth). Returns the bytes and the Chunk record's offset."""
    import zlib
    import zstandard
    import lz4.frame
    if packed is None:
        packed = {b"": lambda b: b, b"zstd": lambda b: zstandard.ZstdCompressor().compress(b),
                  b"lz4": lambda b: lz4.frame.compress(b)}[compression](records)
    chunk = struct.pack("<QQQI", 0, 0, len(records) if usize is None else usize,
                        zlib.crc32(records) if crc is None else crc)
    chunk += mcap_str(compression) + struct.pack("<Q", len(packed)) + packed
    head = b"\x89MCAP0\r\n" + mcap_record(0x01, mcap_str(b"cdm") + mcap_str(b"test"))
    return head + mcap_record(0x06, chunk), len(head)


def test_hostile_compressed_chunks(tmp_path):
    """Decompression is bounded by the size a chunk announces, itself capped
    by the size a recording may have (2 GiB); the CRC covers the
    decompressed records."""
    schema = mcap_record(0x03, struct.pack("<H", 1) + mcap_str(b"cdm.report.v1") + mcap_str(b"") + mcap_str(b""))
    records = schema * 200
    cases = {
        # claims more than the cap: refused before any memory is taken
        "huge": (chunk_file(records, b"zstd", usize=3 << 30), "past the 2147483648 bytes"),
        "huge_lz4": (chunk_file(records, b"lz4", usize=2**63), "past the 2147483648 bytes"),
        # claims more than its compressed bytes can make (under the cap)
        "bomb": (chunk_file(records, b"zstd", usize=1 << 30), "more than zstd can make"),
        "bomb_lz4": (chunk_file(records, b"lz4", usize=1 << 24), "more than lz4 can make"),
        # decompresses to more than it claims
        "short": (chunk_file(records, b"zstd", usize=100), "zstd chunk announces 100 bytes"),
        "short_lz4": (chunk_file(records, b"lz4", usize=100), "lz4 chunk decompresses to more than the 100"),
        # and to less
        "long_lz4": (chunk_file(records, b"lz4", usize=len(records) + 1), "lz4 chunk decompresses to"),
        # a wrong CRC of the decompressed records
        "crc": (chunk_file(records, b"zstd", crc=1), "chunk CRC mismatch"),
        "crc_lz4": (chunk_file(records, b"lz4", crc=1), "chunk CRC mismatch"),
        # not compressed as it says, or an unknown compression
        "garbage": (chunk_file(records, b"zstd", packed=bytes(16)), "zstd"),
        "garbage_lz4": (chunk_file(records, b"lz4", packed=bytes(16)), "lz4"),
        "bz2": (chunk_file(records, b"bz2", packed=records), "\"bz2\""),
    }
    for name, ((data, at), expect) in cases.items():
        path = tmp_path / (name + ".mcap")
        path.write_bytes(data)
        rc, err = replay_error(path)
        assert rc == 1 and ("byte %d:" % at) in err and expect in err, (name, err)
    # The same records, honestly compressed, are read (and refused only for
    # not being a cdm recording).
    for comp in (b"zstd", b"lz4", b""):
        path = tmp_path / "good.mcap"
        path.write_bytes(chunk_file(records, comp)[0])
        rc, err = replay_error(path)
        assert rc == 1 and "cdm.device" in err, (comp, err)


def test_older_recording_with_json_poses_replays(tmp_path):
    """A cdm recording in the JSON layout (JSON poses, uncompressed chunks,
    monotonic log times, no clock_offset_ns): its reports play at their
    log times, byte for byte."""
    old = os.path.join(SRC, "tests", "fuzz", "corpus", "fuzz_mcap", "four_reports.mcap")
    with open(old, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        encodings = {c.topic: c.message_encoding for c in reader.get_summary().channels.values()}
        reports = [(m.log_time, m.data) for _, c, m in reader.iter_messages() if c.topic == "/cdm/report"]
    assert encodings["/cdm/pose"] == "json" and len(reports) == 4
    out = tmp_path / "old.cdmrec"
    r = cdm("export", old, str(out))
    assert r.returncode == 0, r.stderr
    assert cdmrec_records(out)[1] == reports
