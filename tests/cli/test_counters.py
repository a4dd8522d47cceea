"""The device's counters against what the simulator sent, for every fault of
sim: at 100 Hz, 1 kHz and 100 kHz; and a recording of each, replayed,
counts exactly what the live device counted (docs/reliability.md,
"Counters" and "Recordings keep every report").

The simulated session is a short scripted jig walk (10 + 4 positions x 30
reports = 130 reports, k = 0..129, then the end of the stream), unpaced
(realtime=0: the counts, not the timing, are under test; the rate sets the
device clock's step, which the sequence bound reads). Each fault strikes at
report 20, so the expected counters follow from the fault plan alone.
"""
import json
import os

import pytest

from conftest import cdm

N = 130  # reports the scripted session sends
SESSION = "motion=jig&jig_n=2&jig_heights=50&jig_samples=20&jig_transit=10&noise=0"
RATES = [100, 1000, 100000]

# fault option -> (counters that differ from zero, reports published)
FAULTS = {
    "": ({}, N),
    "drop=20": ({"dropped": 1}, N - 1),
    "duplicate=20": ({"out_of_order": 1}, N),
    # 21 comes first (20 counted missing), then 20 late: discarded.
    "reorder=20": ({"dropped": 1, "out_of_order": 1}, N - 1),
    "seq_reset=20": ({"restarts": 1}, N),  # counts from 0 again: no number missing
    "seq_flip=20": ({"sequence_jumps": 2}, N),  # there and back
    "clock_wrap=20": ({}, N),
    "saturate=20:5": ({"out_of_workspace": 5}, N),
}
for kind in ("short", "report_id", "version", "quat_zero", "quat_norm"):
    FAULTS["malformed=%s:20" % kind] = ({"malformed": 1, "dropped": 1}, N - 1)

COUNTERS = ("reports", "dropped", "malformed", "out_of_order", "sequence_jumps", "restarts", "out_of_workspace",
            "reconnects", "replay_truncated_bytes")


def record(tmp_path, uri, name):
    out = tmp_path / name
    r = cdm("record", uri, str(out), "--json")
    assert r.returncode == 0, r.stderr
    return out, json.loads(r.stdout)


def replay_stats(path):
    r = cdm("stream", "replay:%s?speed=0" % path, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    assert summary["summary"] and summary["end_of_stream"]
    return {k: summary[k] for k in COUNTERS}


@pytest.mark.parametrize("rate", RATES)
@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_counters_match_what_the_simulator_sent(tmp_path, rate, fault):
    nonzero, reports = FAULTS[fault]
    uri = "sim:?realtime=0&rate=%d&%s" % (rate, SESSION) + ("&" + fault if fault else "")
    expected = {k: 0 for k in COUNTERS}
    expected.update(nonzero)
    expected["reports"] = reports
    for name in ("live.cdmrec", "live.mcap"):
        out, live = record(tmp_path, uri, name)
        assert live["stats"] == expected, (uri, live)
        # Every report the reader discarded is in the file.
        assert live["rejected"] == live["stats"]["malformed"] + live["stats"]["out_of_order"]
        assert live["samples"] == reports
        assert replay_stats(out) == live["stats"], (uri, name)


def test_export_keeps_the_rejected_reports(tmp_path):
    """A recording exported to another format keeps its rejected reports:
    the export replays it, and its counters are the original's."""
    uri = "sim:?realtime=0&%s&malformed=version:20&duplicate=40&reorder=60" % SESSION
    src, live = record(tmp_path, uri, "src.mcap")
    out = tmp_path / "copy.cdmrec"
    r = cdm("export", str(src), str(out))
    assert r.returncode == 0, r.stderr
    assert "3 rejected ones" in r.stdout, r.stdout
    assert replay_stats(out) == live["stats"]


def test_mcap_names_each_rejection(tmp_path):
    """MCAP logs why each report was discarded on /cdm/rejected, in the
    message definition of examples/ros2/cdm_msgs/msg/Rejected.msg."""
    mcap_reader = pytest.importorskip("mcap.reader")
    uri = "sim:?realtime=0&%s&malformed=quat_zero:20&duplicate=40" % SESSION
    out, live = record(tmp_path, uri, "r.mcap")
    assert live["rejected"] == 2
    with open(out, "rb") as f:
        reader = mcap_reader.make_reader(f)
        msgs = [(s, c, m) for s, c, m in reader.iter_messages(topics=["/cdm/rejected"])]
    assert len(msgs) == 2
    schema = msgs[0][0]
    assert schema.name == "cdm_msgs/msg/Rejected" and schema.encoding == "ros2msg"
    own = open(os.path.join(os.environ["CDM_SOURCE_DIR"], "examples", "ros2", "cdm_msgs", "msg",
                            "Rejected.msg")).read()
    assert schema.data.decode().startswith(own)
    bodies = [m.data for _, _, m in msgs]
    # CDR: encapsulation (4), Time (8), kind (1), padding (3), string length (4), text.
    kinds = [b[12] for b in bodies]
    texts = [b[20:20 + int.from_bytes(b[16:20], "little") - 1].decode() for b in bodies]
    assert kinds == [1, 2], kinds
    assert "input report rejected" in texts[0] and "quaternion" in texts[0], texts[0]
    assert "duplicate or a late report" in texts[1], texts[1]


def test_disconnection_replays_with_the_same_losses(tmp_path):
    """A device unplugged for 150 ms mid-session (paced: the unplug takes
    real time): the recording has no record of the unplug itself, so a
    replay counts no reconnection, but every other counter, the reports
    lost while it was away included, comes out as the live one."""
    # 4 x 210 + 10 reports (0.85 s at 1 kHz): the reader retries every 250 ms,
    # so the walk must outlast the unplug and the retry.
    uri = "sim:?rate=1000&motion=jig&jig_n=2&jig_heights=50&jig_samples=200&jig_transit=10&disconnect=20:150"
    out, live = record(tmp_path, uri, "d.cdmrec")
    st = live["stats"]
    assert st["reconnects"] == 1
    assert st["sequence_jumps"] == 0 and st["restarts"] == 0
    # The reports sampled while unplugged (about 150 at 1 kHz) and until
    # the reader came back are lost, and every number from the first to the
    # last arrived or was counted lost.
    assert st["dropped"] >= 150 and st["reports"] + st["dropped"] == 850, st
    rep = replay_stats(out)
    st = dict(st, reconnects=0)
    assert rep == st, (rep, st)
