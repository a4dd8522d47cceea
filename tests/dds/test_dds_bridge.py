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
- types and hashes: every writer's USER_DATA is "typehash=RIHS01_...;" as
  rmw_cyclonedds writes it, checked against REP-2011's hashing done here
  from the .msg definitions, itself checked against the hashes ROS 2's
  generated code carries; the gripper is a sensor_msgs/JointState and the
  health goes to /diagnostics (diagnostic_msgs/DiagnosticArray) too.
- domains: ROS_DOMAIN_ID alone, --domain overriding it, a bad value refused.
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

TYPES = {"pose": T.PoseStamped, "joy": T.Joy, "gripper": T.JointState, "status": T.Status,
         "diagnostics": T.DiagnosticArray}
TYPE_NAMES = {"pose": "geometry_msgs::msg::dds_::PoseStamped_", "joy": "sensor_msgs::msg::dds_::Joy_",
              "gripper": "sensor_msgs::msg::dds_::JointState_", "status": "cdm_msgs::msg::dds_::Status_",
              "diagnostics": "diagnostic_msgs::msg::dds_::DiagnosticArray_"}
ROS_TYPES = {leaf: n.replace("::dds_::", "::").replace("::", "/")[:-1] for leaf, n in TYPE_NAMES.items()}
_counter = itertools.count()


def realtime_ns():
    return time.clock_gettime_ns(time.CLOCK_REALTIME)


class Bridge:
    """`cdm bridge URI --dds` on a domain and prefix of its own, so that runs
    on the same machine never see each other's topics."""

    def __init__(self, uri, seconds, *extra, domain_from="option"):
        """domain_from: "option" (--domain), "env" (ROS_DOMAIN_ID only) or
        "both" (ROS_DOMAIN_ID set to another domain, --domain overriding it)."""
        rng = random.Random(os.getpid() * 7919 + next(_counter))
        self.domain = rng.randint(1, 200)
        self.prefix = "cdmtest_%d_%d" % (os.getpid(), next(_counter))
        self.serial = "CDMSIM0001"
        self.topics = T.topic_names(self.serial, self.prefix)
        self.topics["diagnostics"] = T.DIAGNOSTICS_TOPIC
        self.base = "rt/%s/%s/" % (self.prefix, self.serial)
        env = dict(os.environ)
        env.pop("ROS_DOMAIN_ID", None)
        argv = [CLI, "bridge", uri, "--dds", "--prefix", self.prefix, "--seconds", str(seconds), *extra]
        if domain_from in ("option", "both"):
            argv += ["--domain", str(self.domain)]
        if domain_from == "env":
            env["ROS_DOMAIN_ID"] = str(self.domain)
        if domain_from == "both":
            env["ROS_DOMAIN_ID"] = str(self.domain + 1)
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

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
            # status: what the bridge offers; diagnostics: ROS 2's default
            # subscription (reliable, volatile), as its tools subscribe.
            qos = (Qos(Policy.Reliability.Reliable(0), Policy.History.KeepLast(1000), Policy.Durability.TransientLocal)
                   if leaf == "status" else
                   Qos(Policy.Reliability.Reliable(0), Policy.History.KeepLast(1000), Policy.Durability.Volatile)
                   if leaf == "diagnostics" else Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1000)))
            self.readers[leaf] = DataReader(self.dp, topic, qos=qos)
        self.got = {leaf: [] for leaf in TYPES}
        self.publications = BuiltinDataReader(self.dp, BuiltinTopicDcpsPublication)
        self.type_names = {}
        self.user_data = {}

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
                    ud = ep.qos[Policy.Userdata] if Policy.Userdata in ep.qos else None
                    self.user_data[ep.topic_name] = ud.data if ud is not None else b""
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
        # One joint, its opening: the simulated jaw, 0..0.6 rad, plus Hall noise.
        assert list(g.name) == ["grip"] and len(g.position) == 1 and not g.velocity and not g.effort, g
        assert 0.0 - 0.05 < g.position[0] < 0.6 + 0.05 and g.header.frame_id == "master_base"
    # Every writer carries its ROS 2 type hash the way rmw_cyclonedds writes it.
    for leaf, ros_type in ROS_TYPES.items():
        assert sub.user_data.get(bridge.topics[leaf]) == b"typehash=%s;" % rihs01(ros_type).encode(), \
            (leaf, sub.user_data.get(bridge.topics[leaf]))
    # /diagnostics: the device's entry, OK while the simulation runs.
    mine = [st for a, _ in sub.got["diagnostics"] for st in a.status if st.hardware_id == bridge.serial]
    assert mine, "no /diagnostics entry for %s" % bridge.serial
    for st in mine:
        assert st.level == 0 and st.message == "ok" and st.name == "cdm bridge: " + bridge.serial, st
        values = {kv.key: kv.value for kv in st.values}
        assert int(values["reports"]) >= int(values["published"]) > 0 and values["compensated"] == "false", values


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
    # /diagnostics says the same: WARN, stale, once the reports stop.
    # (Volatile, as ROS 2 publishes it: a late subscriber sees only what follows.)
    levels = [(st.level, st.message) for a, _ in sub.got["diagnostics"] for st in a.status]
    first = next(i for i, lv in enumerate(levels) if lv[0] != 0)
    assert all(lv == (0, "ok") for lv in levels[:first]), levels[:first]
    assert all(lv[0] == 1 and lv[1].startswith("stale") for lv in levels[first:]), levels[first:]
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

def rihs01(ros_type):
    """REP-2011's type hash, computed here from the .msg definitions (field
    names and types; default values are not hashed): the JSON of the type's
    description and those it refers to, sorted by name, as
    rosidl_generator_type_description serialises it, through SHA-256."""
    import hashlib
    import json
    prim = {"int32": 6, "uint32": 7, "uint64": 9, "float32": 10, "float64": 11, "bool": 15, "byte": 16,
            "string": 17}
    msgs = {
        "builtin_interfaces/msg/Time": "int32 sec; uint32 nanosec",
        "std_msgs/msg/Header": "builtin_interfaces/msg/Time stamp; string frame_id",
        "std_msgs/msg/String": "string data",
        "geometry_msgs/msg/Point": "float64 x; float64 y; float64 z",
        "geometry_msgs/msg/Quaternion": "float64 x; float64 y; float64 z; float64 w",
        "geometry_msgs/msg/Pose": "geometry_msgs/msg/Point position; geometry_msgs/msg/Quaternion orientation",
        "geometry_msgs/msg/PoseStamped": "std_msgs/msg/Header header; geometry_msgs/msg/Pose pose",
        "sensor_msgs/msg/Joy": "std_msgs/msg/Header header; float32[] axes; int32[] buttons",
        "sensor_msgs/msg/JointState": "std_msgs/msg/Header header; string[] name; float64[] position; "
                                      "float64[] velocity; float64[] effort",
        "diagnostic_msgs/msg/KeyValue": "string key; string value",
        "diagnostic_msgs/msg/DiagnosticStatus": "byte level; string name; string message; string hardware_id; "
                                                "diagnostic_msgs/msg/KeyValue[] values",
        "diagnostic_msgs/msg/DiagnosticArray": "std_msgs/msg/Header header; "
                                               "diagnostic_msgs/msg/DiagnosticStatus[] status",
    }
    status = open(os.path.join(SRC, "examples", "ros2", "cdm_msgs", "msg", "Status.msg")).read()
    msgs["cdm_msgs/msg/Status"] = "; ".join(
        line.replace("std_msgs/Header", "std_msgs/msg/Header") for line in status.splitlines()
        if line.strip() and not line.startswith("#"))

    def fields(name):
        out = []
        for decl in msgs[name].split("; "):
            t, n = decl.split()
            seq = t.endswith("[]")
            t = t[:-2] if seq else t
            out.append((n, prim.get(t, 1) + (144 if seq else 0), "" if t in prim else t))
        return out

    def desc(name):
        return {"type_name": name, "fields": [
            {"name": n, "type": {"type_id": i, "capacity": 0, "string_capacity": 0, "nested_type_name": nested}}
            for n, i, nested in fields(name)]}

    refs, todo = set(), [ros_type]
    while todo:
        for _, _, nested in fields(todo.pop()):
            if nested and nested not in refs:
                refs.add(nested)
                todo.append(nested)
    text = json.dumps({"type_description": desc(ros_type),
                       "referenced_type_descriptions": [desc(r) for r in sorted(refs)]}, separators=(", ", ": "))
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()


def test_type_hash_matches_ros2():
    """The hashing above gives the hashes ROS 2's generated code carries
    (rosidl's *__get_type_hash of std_msgs, geometry_msgs, sensor_msgs,
    diagnostic_msgs): the reference the bridge's USER_DATA is checked with."""
    assert rihs01("std_msgs/msg/String") == \
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    assert rihs01("geometry_msgs/msg/PoseStamped") == \
        "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
    assert rihs01("diagnostic_msgs/msg/DiagnosticArray") == \
        "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"
    assert rihs01("sensor_msgs/msg/JointState").startswith(
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179")


@pytest.mark.parametrize("domain_from", ["env", "both"])
def test_domain_from_ros_domain_id(domain_from):
    """ROS_DOMAIN_ID alone picks the domain; --domain overrides it (the
    environment then names another domain, where nothing may arrive)."""
    bridge = Bridge("sim:", 3, domain_from=domain_from)
    sub = Subscriber(bridge)
    other = DomainParticipant(bridge.domain + 1)
    stray = DataReader(other, Topic(other, bridge.topics["pose"], T.PoseStamped),
                       qos=Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(100)))
    assert sub.collect(lambda s: len(s.got["pose"]) > 50, 10), "no poses on domain %d" % bridge.domain
    out = bridge.finish()
    assert "DDS domain %d:" % bridge.domain in out, out
    assert not stray.take(N=100), "poses on domain %d as well" % (bridge.domain + 1)


def test_bad_ros_domain_id():
    for bad in ("seven", "233", "-1", "7x"):
        env = dict(os.environ, ROS_DOMAIN_ID=bad)
        r = subprocess.run([CLI, "bridge", "sim:", "--dds", "--seconds", "1"], capture_output=True, text=True,
                           timeout=30, env=env)
        assert r.returncode == 2 and "ROS_DOMAIN_ID=\"%s\"" % bad in r.stderr, (bad, r)


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
