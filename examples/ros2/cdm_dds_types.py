"""The bridge's DDS types for Python's `cyclonedds` package (pip install cyclonedds).

The same types as src/bridge/idl/*.idl, with ROS 2's DDS names (a ROS 2 type
"pkg/msg/T" is the DDS type "pkg::msg::dds_::T_"): a program without ROS 2
reads `cdm bridge --dds` with these, and tests/dds checks them against the
bridge. Field names and order are the ROS .msg files'.

    from cdm_dds_types import PoseStamped, topic_names, pose_qos, status_qos
"""
from dataclasses import dataclass, field

from cyclonedds.core import Policy, Qos
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import byte, float32, float64, int32, sequence, uint32, uint64
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass
class Joy(IdlStruct, typename="sensor_msgs::msg::dds_::Joy_"):
    header: Header = field(default_factory=Header)
    axes: sequence[float32] = field(default_factory=list)
    buttons: sequence[int32] = field(default_factory=list)


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: byte = 0  # OK 0, WARN 1, ERROR 2, STALE 3 (an IDL octet)
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


# The device's health, for ROS 2 tools (rqt_robot_monitor, the aggregator).
DIAGNOSTICS_TOPIC = "rt/diagnostics"


@dataclass
class Status(IdlStruct, typename="cdm_msgs::msg::dds_::Status_"):
    header: Header = field(default_factory=Header)
    stale: bool = False
    disconnected: bool = False
    compensated: bool = False
    out_of_workspace: bool = False
    end_of_stream: bool = False
    flags: uint32 = 0
    report_sequence: uint32 = 0
    device_time_us: uint64 = 0
    reports: uint64 = 0
    dropped: uint64 = 0
    malformed: uint64 = 0
    published: uint64 = 0
    skipped: uint64 = 0


# Joy.buttons, in this order (each 0 or 1).
JOY_BUTTONS = ("clutch", "aux", "mark")


def topic_names(serial, prefix="cdm"):
    """The bridge's DDS topic names: {"pose": "rt/cdm/SERIAL/pose", ...}."""
    return {leaf: "rt/%s/%s/%s" % (prefix, serial, leaf) for leaf in ("pose", "joy", "gripper", "status")}


def stamp_ns(header):
    """A header's stamp as nanoseconds of ROS time (CLOCK_REALTIME)."""
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


# What the bridge offers (docs/ros2.md): pose, joy and gripper best effort,
# keep last 1; status reliable, transient local, keep last 10; diagnostics
# ROS 2's default (reliable, volatile, keep last 10).
def pose_qos():
    return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1))


def status_qos():
    return Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10),
               Policy.Durability.TransientLocal)
