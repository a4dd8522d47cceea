"""`cdm bridge --dds` end to end: the bridge on sim: publishes over Cyclone DDS
on loopback (CYCLONEDDS_URI=tests/dds/cyclonedds_lo.xml, set by ctest), and
subscribers read it as a ROS 2 node would see it.

- test_poses_match_the_simulation: Python subscriber (the `cyclonedds` package,
  the types of examples/ros2/cdm_dds_types.py): the announced DDS type names,
  then every received pose matched (through the status topic's stamp and
  report sequence) with the same simulation replayed in this process: the
  position equals the driver's own in metres and lies within the sensor noise
  of the simulator's truth, the quaternion is the driver's in x,y,z,w order,
  and the joy buttons are the report's. The C subscriber (dds_sub check) runs
  against the same bridge.
- test_stale_when_the_device_stalls: sim:?stall_after=N: poses stop at report
  N-1 and the status turns stale, reliably delivered.
- test_disconnect_and_reconnect: sim:?disconnect=500:400: disconnected, then
  back, the lost reports counted.
- usage errors: no --dds, a bad --prefix; the status type agrees in the IDL,
  the ROS .msg and the Python type.
"""
import ctypes
import itertools
import math
import os
import random
import subprocess
import sys
import threading
import time

import pytest

SRC = os.environ["CDM_SOURCE_DIR"]
CLI = os.environ["CDM_CLI"]
C_SUB = os.environ["CDM_DDS_SUB"]
sys.path.insert(0, os.path.join(SRC, "examples", "ros2"))
try:
    from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
except ImportError as e:  # a set-up machine has it: fail, never skip
    raise ImportError("tests/dds needs Python's cyclonedds (scripts/setup.sh installs it: "
                      "pip install cyclonedds==11.0.1): %s" % e) from e
import cdm  # noqa: E402
from cdm import _native  # noqa: E402
import cdm_dds_types as T  # noqa: E402

TYPES = {"pose": T.PoseStamped, "joy": T.Joy, "gripper": T.Float64, "status": T.Status}
TYPE_NAMES = {"pose": "geometry_msgs::msg::dds_::PoseStamped_", "joy": "sensor_msgs::msg::dds_::Joy_",
              "gripper": "std_msgs::msg::dds_::Float64_", "status": "cdm_msgs::msg::dds_::Status_"}
_counter = itertools.count()


def realtime_ns():
    return time.clock_gettime_ns(time.CLOCK_REALTIME)


class Bridge:
    """`cdm bridge URI --dds` on a domain and prefix of its own, so that runs
    on the same machine never see each other's topics."""

    def __init__(self, uri, seconds, *extra):
        self.domain = random.Random(os.getpid() * 7919 + next(_counter)).randint(1, 200)
        self.prefix = "cdmtest_%d_%d" % (os.getpid(), next(_counter))
        self.serial = "CDMSIM0001"
        self.topics = T.topic_names(self.serial, self.prefix)
        self.base = "rt/%s/%s/" % (self.prefix, self.serial)
        argv = [CLI, "bridge", uri, "--dds", "--domain", str(self.domain), "--prefix", self.prefix,
                "--seconds", str(seconds), *extra]
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def finish(self, timeout=30):
        out, err = self.proc.communicate(timeout=timeout)
        assert self.proc.returncode == 0, "cdm bridge exited %d: %s%s" % (self.proc.returncode, out, err)
        return out


class Subscriber:
    """Readers for the four topics; collect() takes what arrives, with the
    receive time (CLOCK_REALTIME), until a condition holds or time is up."""

    def __init__(self, bridge):
        self.dp = DomainParticipant(bridge.domain)
        # Deep reader histories: the test wants every sample, not the newest
        # (a teleop subscriber would keep 1, as the writer does).
        self.readers = {}
        for leaf, cls in TYPES.items():
            topic = Topic(self.dp, bridge.topics[leaf], cls)
            qos = (Qos(Policy.Reliability.Reliable(0), Policy.History.KeepLast(1000), Policy.Durability.TransientLocal)
                   if leaf == "status" else Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1000)))
            self.readers[leaf] = DataReader(self.dp, topic, qos=qos)
        self.got = {leaf: [] for leaf in TYPES}
        self.publications = BuiltinDataReader(self.dp, BuiltinTopicDcpsPublication)
        self.type_names = {}

    def collect(self, until, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for leaf, r in self.readers.items():
                for s in r.take(N=1000):
                    if isinstance(s, TYPES[leaf]):
                        self.got[leaf].append((s, realtime_ns()))
            for ep in self.publications.take(N=100):
                if hasattr(ep, "topic_name"):
                    self.type_names[ep.topic_name] = ep.type_name
            if until(self):
                return True
            time.sleep(0.002)
        return False


def replay_simulation(sim_options, seqs):
    """The bridge's simulation again, in this process and unpaced
    (realtime=0): the same seed gives the same reports. Returns
    {sequence: (pose, truth position mm)} for `seqs`."""
    need, top = set(seqs), max(seqs)
    poses, reached, release = {}, threading.Event(), threading.Event()

    def on_sample(s):
        if s.pose.sequence in need:
            poses[s.pose.sequence] = s.pose
        if s.pose.sequence >= top and not reached.is_set():
            reached.set()
            release.wait(60)  # hold the reader: the truth of `seqs` stays in the simulator's memory

    out = {}
    with cdm.open("sim:?%s&realtime=0" % sim_options, on_sample=on_sample) as dev:
        try:
            assert reached.wait(60), "the replayed simulation never reached report %d" % top
            for seq in need:
                p = (ctypes.c_double * 3)()
                rc = _native.lib().cdm_sim_truth(dev._handle("cdm_sim_truth"), seq, p)
                assert rc == 0, "cdm_sim_truth(%d) = %d" % (seq, rc)
                out[seq] = (poses[seq], tuple(p))
        finally:
            release.set()
    return out


def test_poses_match_the_simulation():
    sim = "seed=23"
    bridge = Bridge("sim:?" + sim, 6, "--status-rate", "100", "--frame-id", "master_base")
    c_sub = subprocess.Popen([C_SUB, "check", str(bridge.domain), bridge.base, "master_base", "500", "10"],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    sub = Subscriber(bridge)
    # 2 s of data once the first pose is in (discovery on loopback takes well under a second).
    assert sub.collect(lambda s: s.got["pose"], 10), "no pose within 10 s"
    sub.collect(lambda s: False, 2.0)
    c_out, _ = c_sub.communicate(timeout=30)
    bridge.finish()
    assert c_sub.returncode == 0, "C subscriber:\n" + c_out

    for leaf, name in TYPE_NAMES.items():
        assert sub.type_names.get(bridge.topics[leaf]) == name, (leaf, sub.type_names)
    for leaf in TYPES:
        assert sub.got[leaf], "nothing on " + bridge.topics[leaf]

    # A status names the stamp and report sequence of the newest pose
    # published when it was sent: that pairs poses with reports.
    by_stamp = {T.stamp_ns(p.header): (p, t) for p, t in sub.got["pose"]}
    joy_by_stamp = {T.stamp_ns(j.header): j for j, _ in sub.got["joy"]}
    pairs = {}
    for st, _ in sub.got["status"]:
        assert not (st.stale or st.disconnected or st.end_of_stream or st.out_of_workspace), st
        stamp = T.stamp_ns(st.header)
        if stamp in by_stamp:
            pairs[st.report_sequence] = by_stamp[stamp][0]
    # 100 statuses a second for 2 s; at most a few poses are lost on loopback.
    assert len(pairs) >= 50, "only %d poses could be paired with a report" % len(pairs)
    ref = replay_simulation(sim, pairs)

    errs = []
    for seq, msg in pairs.items():
        pose, truth = ref[seq]
        got_mm = (msg.pose.position.x * 1e3, msg.pose.position.y * 1e3, msg.pose.position.z * 1e3)
        # The bridge's metres are the driver's mm / 1000: equal to 1e-9 mm
        # (double rounding of numbers below 1000 mm is ~1e-13 mm).
        for k in range(3):
            assert abs(got_mm[k] - pose.position[k]) < 1e-9, (seq, got_mm, pose.position)
        q = msg.pose.orientation
        assert (q.w, q.x, q.y, q.z) == pytest.approx(pose.orientation, abs=1e-15), (seq, q, pose.orientation)
        assert msg.header.frame_id == "master_base"
        joy = joy_by_stamp.get(T.stamp_ns(msg.header))
        if joy is not None:
            assert list(joy.buttons) == [int(bool(pose.buttons & b)) for b in (1, 2, 4)], (seq, joy, pose.buttons)
        errs.append(math.dist(got_mm, truth))
    # Against the simulator's truth: pot noise 0.05 mm per cable through the
    # triangulation gives a position error of about 0.1 mm RMS in the middle
    # of the workspace (`cdm stream sim: --truth` shows the same); 1 mm is
    # ten standard deviations, and far below the 1000x of a unit mix-up.
    rms = math.sqrt(sum(e * e for e in errs) / len(errs))
    assert rms < 0.3 and max(errs) < 1.0, "error vs truth: RMS %.3f mm, max %.3f mm" % (rms, max(errs))
    # Stamps: the host clock at the report's receipt, before our receipt.
    lat = sorted(t - T.stamp_ns(p.header) for p, t in sub.got["pose"])
    assert lat[0] > 0, "a pose stamped after it was received"
    for g, _ in sub.got["gripper"]:
        assert 0.0 - 0.05 < g.data < 0.6 + 0.05  # the simulated jaw: 0..0.6 rad, plus Hall noise


def test_stale_when_the_device_stalls():
    bridge = Bridge("sim:?stall_after=400", 4)
    sub = Subscriber(bridge)
    assert sub.collect(lambda s: any(st.stale for st, _ in s.got["status"]), 10), \
        "no stale status within 10 s: %s" % [st for st, _ in sub.got["status"]][-3:]
    sub.collect(lambda s: False, 0.3)  # poses that were on the way
    bridge.finish()
    statuses = [st for st, _ in sub.got["status"]]
    first_stale = next(i for i, st in enumerate(statuses) if st.stale)
    assert first_stale > 0 and not statuses[first_stale - 1].stale  # fresh before the stall, then stale
    st = statuses[first_stale]
    # The stall: reports 0..399 were sent; the stale status names the last.
    assert st.report_sequence == 399 and st.reports == 400, st
    assert not st.disconnected and not st.end_of_stream
    assert all(s.stale for s in statuses[first_stale:]), "a stalled device turned fresh again"
    # No pose after the stall: the newest one received is report 399's.
    newest = max(sub.got["pose"], key=lambda pt: T.stamp_ns(pt[0].header))[0]
    assert T.stamp_ns(newest.header) == T.stamp_ns(st.header)


def test_disconnect_and_reconnect():
    """sim:?disconnect=500:400: unplugged at report 500 for 400 ms, then back
    with the same serial. The status says disconnected, then not, with the
    lost reports counted; poses resume."""
    bridge = Bridge("sim:?disconnect=500:400", 3)
    sub = Subscriber(bridge)
    back = lambda s: any(st.disconnected for st, _ in s.got["status"]) and not s.got["status"][-1][0].disconnected
    assert sub.collect(back, 10), [st for st, _ in sub.got["status"]][-3:]
    sub.collect(lambda s: False, 0.3)
    bridge.finish()
    statuses = [st for st, _ in sub.got["status"]]
    i = next(i for i, st in enumerate(statuses) if st.disconnected)
    assert statuses[i].report_sequence == 499, statuses[i]  # the last report before the unplug
    j = next(j for j in range(i, len(statuses)) if not statuses[j].disconnected)
    # The device samples on while unplugged: ~400 reports at 1 kHz are lost.
    assert statuses[j].report_sequence > 499 and statuses[j].dropped > 300, statuses[j]
    assert max(T.stamp_ns(p.header) for p, _ in sub.got["pose"]) > T.stamp_ns(statuses[i].header)  # poses resumed

def test_usage_errors():
    r = subprocess.run([CLI, "bridge", "sim:"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "--dds" in r.stderr, r
    r = subprocess.run([CLI, "bridge", "sim:", "--dds", "--prefix", "cdm//x"], capture_output=True, text=True,
                       timeout=30)
    assert r.returncode == 2 and "--prefix" in r.stderr and "empty token" in r.stderr, r
    r = subprocess.run([CLI, "bridge", "sim:", "--dds", "--prefix", "cdm/1st"], capture_output=True, text=True,
                       timeout=30)
    assert r.returncode == 2 and "starts with a digit" in r.stderr, r


def test_status_type_agrees_everywhere():
    """The status type is written three times (the IDL the bridge compiles,
    the ROS 2 .msg for ROS users, the Python dataclass): same fields, same
    order, same types."""
    import dataclasses
    import re
    idl = open(os.path.join(SRC, "src", "bridge", "idl", "cdm_msgs.idl")).read()
    body = re.search(r"struct Status_\s*{(.*?)};", idl, re.S).group(1)
    body = re.sub(r"//[^\n]*", "", body)
    idl_fields = [(" ".join(m.group(1).split()), m.group(2)) for m in re.finditer(r"([\w:\s]+?)\s+(\w+)\s*;", body)]
    to_msg = {"boolean": "bool", "unsigned long": "uint32", "unsigned long long": "uint64",
              "std_msgs::msg::dds_::Header_": "std_msgs/Header"}
    msg = open(os.path.join(SRC, "examples", "ros2", "cdm_msgs", "msg", "Status.msg")).read()
    msg_fields = [tuple(line.split()) for line in msg.splitlines() if line.strip() and not line.startswith("#")]
    assert [(to_msg[t], n) for t, n in idl_fields] == msg_fields
    assert [f.name for f in dataclasses.fields(T.Status)] == [n for _, n in idl_fields]
