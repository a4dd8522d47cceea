#!/usr/bin/env python3
"""A ROS 2 node that listens to `cdm bridge --dds`: run as is where ROS 2 is installed.

    # the master's machine (no ROS 2 needed there)
    cdm bridge sim: --dds                      # or hid:/dev/hidrawN, serial:SN
    # a ROS 2 machine on the same network and ROS_DOMAIN_ID (the bridge's --domain)
    python3 ros2_subscriber.py --serial CDMSIM0001

Prints the pose (metres, frame of the master's base), the buttons, the
gripper (sensor_msgs/JointState, joint "grip"), the status when it changes,
and the master's entry on /diagnostics. The status topic has cdm's own type
(cdm_msgs/msg/Status): build ./cdm_msgs in a colcon workspace and source it to
see it; without it the node says so and listens to the rest. Not runnable in
cdm's own tree (no ROS 2 there): tests/dds reads the same topics at the DDS
level, which is what this node sees through rmw.
"""
import argparse

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState, Joy

try:
    from cdm_msgs.msg import Status
except ImportError:  # cdm_msgs not built in this workspace
    Status = None

# What the bridge offers (docs/ros2.md): pose, joy and gripper best effort,
# keep last 1 (a ROS default reliable subscription would not match them);
# status reliable and transient local, so a late joiner gets the current one.
SENSOR = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST, depth=1)
STATUS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=10,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL)


class MasterListener(Node):
    def __init__(self, prefix, serial, print_hz):
        super().__init__("cdm_master_listener")
        base = "/%s/%s/" % (prefix, serial)
        self.serial = serial
        self.pose = self.joy = self.grip = None
        self.create_subscription(PoseStamped, base + "pose", self.on_pose, SENSOR)
        self.create_subscription(Joy, base + "joy", lambda m: setattr(self, "joy", m), SENSOR)
        self.create_subscription(JointState, base + "gripper", lambda m: setattr(self, "grip", m), SENSOR)
        # /diagnostics with ROS 2's default QoS, as every diagnostics tool reads it.
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diagnostics, 10)
        if Status is not None:
            self.create_subscription(Status, base + "status", self.on_status, STATUS)
        else:
            self.get_logger().warn("cdm_msgs is not built here: %sstatus is not shown (see README.md)" % base)
        self.poses = 0
        self.create_timer(1.0 / print_hz, self.show)

    def on_pose(self, msg):
        self.pose = msg
        self.poses += 1

    def on_diagnostics(self, a):
        for st in a.status:
            if st.hardware_id == self.serial:
                self.get_logger().info("diagnostics: level %d, %s" % (st.level[0] if isinstance(st.level, bytes)
                                                                       else st.level, st.message))

    def on_status(self, s):
        self.get_logger().info("status: stale %s, disconnected %s, compensated %s, dropped %d, published %d"
                               % (s.stale, s.disconnected, s.compensated, s.dropped, s.published))

    def show(self):
        if self.pose is None:
            self.get_logger().info("waiting for %s poses..." % self.get_namespace())
            return
        p, q = self.pose.pose.position, self.pose.pose.orientation
        buttons = list(self.joy.buttons) if self.joy else []
        grip = self.grip.position[0] if self.grip and self.grip.position else float("nan")
        self.get_logger().info("%d poses; position %.4f %.4f %.4f m, q (x,y,z,w) %.3f %.3f %.3f %.3f, "
                               "buttons (clutch, aux, mark) %s, gripper %.3f rad"
                               % (self.poses, p.x, p.y, p.z, q.x, q.y, q.z, q.w, buttons, grip))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--prefix", default="cdm", help="the bridge's --prefix (default cdm)")
    ap.add_argument("--serial", default="CDMSIM0001", help="the master's serial (`cdm info URI`)")
    ap.add_argument("--print-hz", type=float, default=2.0)
    a, ros_args = ap.parse_known_args()
    rclpy.init(args=ros_args)
    node = MasterListener(a.prefix, a.serial, a.print_hz)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
