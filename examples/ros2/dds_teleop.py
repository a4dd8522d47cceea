#!/usr/bin/env python3
"""Remote teleoperation over DDS: the MuJoCo arm of examples/python driven by
the poses `cdm bridge --dds` publishes, read with Python's `cyclonedds`
package (no ROS 2 needed on either side).

    # the master's machine
    cdm bridge hid:/dev/hidraw3 --dds
    # the robot's machine (same network, same --domain)
    python3 examples/ros2/dds_teleop.py --serial SN --seconds 30
    # both on one machine, the simulated master, the bridge started here:
    python3 examples/ros2/dds_teleop.py --bridge sim: --seconds 10

The arm, the IK, the clutch (Joy button 0) and the motion scaling are
mujoco_teleop.py's; only the source of the pose changes. The arm holds its
target while the status topic says the master is stale or disconnected, and
while no pose has come for 100 ms. At the end it reports how closely the tool
followed the target, as mujoco_teleop.py does (--check: exit 1 unless
feed-forward removed 3/4 of a plain servo's lag, and poses kept coming).
"""
import argparse
import os
import shutil
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "python"))
try:
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
except ImportError:  # pragma: no cover - told to the user
    sys.exit("dds_teleop: needs Python's cyclonedds package (pip install cyclonedds)")
from mujoco_teleop import Arm, TeleopMapper, quat_angle  # noqa: E402  (needs mujoco, numpy)

import cdm_dds_types as T  # noqa: E402


class DdsMaster:
    """The newest pose, clutch and health of one master on DDS."""

    def __init__(self, domain, prefix, serial):
        self.dp = DomainParticipant(domain)
        names = T.topic_names(serial, prefix)
        self.pose_r = DataReader(self.dp, Topic(self.dp, names["pose"], T.PoseStamped), qos=T.pose_qos())
        self.joy_r = DataReader(self.dp, Topic(self.dp, names["joy"], T.Joy), qos=T.pose_qos())
        self.status_r = DataReader(self.dp, Topic(self.dp, names["status"], T.Status), qos=T.status_qos())
        self.pos_mm = self.quat_wxyz = None
        self.clutch = False
        self.healthy = True
        self.last_pose_t = None
        self.poses = 0

    def poll(self):
        for m in self.pose_r.take(N=8):
            if isinstance(m, T.PoseStamped):
                p, q = m.pose.position, m.pose.orientation
                # DDS/ROS: metres, quaternion x,y,z,w; the mapper: mm, w,x,y,z.
                self.pos_mm = np.array([p.x, p.y, p.z]) * 1000.0
                self.quat_wxyz = np.array([q.w, q.x, q.y, q.z])
                self.last_pose_t = time.monotonic()
                self.poses += 1
        for m in self.joy_r.take(N=8):
            if isinstance(m, T.Joy) and len(m.buttons) >= 1:
                self.clutch = bool(m.buttons[0])
        for s in self.status_r.take(N=32):
            if isinstance(s, T.Status):
                self.healthy = not (s.stale or s.disconnected or s.end_of_stream)

    def usable(self, max_age_s=0.1):
        return (self.pos_mm is not None and self.healthy and time.monotonic() - self.last_pose_t < max_age_s)


def start_bridge(uri, domain, prefix, seconds):
    cli = os.environ.get("CDM_CLI") or shutil.which("cdm")
    if not cli:
        sys.exit("dds_teleop: --bridge needs the cdm command (on PATH, or CDM_CLI=path/to/cdm)")
    # An argument vector, never a shell: any URI is passed as it is.
    return subprocess.Popen([cli, "bridge", uri, "--dds", "--domain", str(domain), "--prefix", prefix,
                             "--seconds", str(seconds)], stdout=subprocess.DEVNULL)


def run(master, seconds, scale, control_hz=500.0, first_pose_timeout=10.0):
    arm = Arm()
    tool_pos, tool_quat = arm.tool_pose()
    mapper = TeleopMapper(tool_pos, tool_quat, scale)
    t_wait = time.monotonic()
    while master.pos_mm is None:
        if time.monotonic() - t_wait > first_pose_timeout:
            raise RuntimeError("dds_teleop: no pose on DDS within %.0f s (is the bridge running, same domain?)"
                               % first_pose_timeout)
        master.poll()
        time.sleep(0.005)
    pos_err, rot_err, speeds, held = [], [], [], 0
    prev_target = None
    period = 1.0 / control_hz
    t0 = time.monotonic()
    next_t = period
    while True:
        now = time.monotonic() - t0
        if now >= seconds:
            break
        if now < next_t:
            time.sleep(next_t - now)
        next_t += period
        master.poll()
        # A stale or silent master holds the arm: the clutch's hold, so the
        # tool does not jump when poses come back.
        hold = master.clutch or not master.usable()
        held += hold
        target_p, target_q = mapper.update(master.pos_mm, master.quat_wxyz, hold)
        arm.set_point(arm.solve_ik(target_p, target_q), period)
        arm.step_until(time.monotonic() - t0)
        p, q = arm.tool_pose()
        pos_err.append(np.linalg.norm(p - target_p))
        rot_err.append(quat_angle(q, target_q))
        if prev_target is not None:
            speeds.append(np.linalg.norm(target_p - prev_target) * control_hz)
        prev_target = target_p.copy()
    e = np.array(pos_err) * 1000.0
    speed = float(np.sqrt(np.mean(np.square(speeds)))) if speeds else 0.0
    res = {"cycles": len(e), "poses": master.poses, "held_cycles": int(held),
           "rms_mm": float(np.sqrt(np.mean(e ** 2))), "max_mm": float(e.max()),
           "rms_deg": float(np.degrees(np.sqrt(np.mean(np.square(rot_err))))),
           "servo_lag_mm": speed * 1000.0 * arm.lag_s.max()}
    print("%d control cycles (%d held: clutch, stale or no pose), %d poses received over DDS"
          % (res["cycles"], res["held_cycles"], res["poses"]))
    print("tool tip vs commanded target: RMS %.2f mm, max %.2f mm; orientation RMS %.2f deg "
          "(a plain position servo would lag by %.2f mm)" % (res["rms_mm"], res["max_mm"], res["rms_deg"],
                                                             res["servo_lag_mm"]))
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--domain", type=int, default=0, help="DDS domain (the bridge's --domain; default 0)")
    ap.add_argument("--prefix", default="cdm", help="the bridge's --prefix (default cdm)")
    ap.add_argument("--serial", default="CDMSIM0001", help="the master's serial (default CDMSIM0001, the sim's)")
    ap.add_argument("--bridge", metavar="URI", help="start `cdm bridge URI --dds` here first (one-machine demo)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--scale", type=float, default=0.5, help="tool motion per master motion (default 0.5)")
    ap.add_argument("--check", action="store_true",
                    help="exit 1 unless the arm tracked (as mujoco_teleop --check) and poses kept coming")
    a = ap.parse_args(argv)
    if not a.seconds > 0 or not a.scale > 0:
        ap.error("--seconds and --scale must be positive")
    bridge = start_bridge(a.bridge, a.domain, a.prefix, a.seconds + 15) if a.bridge else None
    try:
        res = run(DdsMaster(a.domain, a.prefix, a.serial), a.seconds, a.scale)
    finally:
        if bridge:
            bridge.terminate()
            bridge.wait(10)
    if a.check:
        # Poses at the device's 1 kHz, best effort on one machine: far more
        # than one per control cycle; fewer than a quarter means DDS is not
        # delivering, whatever the tracking says.
        if res["poses"] < 0.25 * res["cycles"]:
            print("dds_teleop: only %d poses for %d control cycles" % (res["poses"], res["cycles"]))
            return 1
        if not (res["servo_lag_mm"] > 0 and res["rms_mm"] < 0.25 * res["servo_lag_mm"]):
            print("dds_teleop: RMS tracking error %.2f mm is not below a quarter of the plain servo lag %.2f mm"
                  % (res["rms_mm"], res["servo_lag_mm"]))
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
