"""ROS 2 message types for Eclipse Cyclone DDS's Python binding, declared as ROS 2's rmw
layers declare them on the wire: the `pkg::msg::dds_::Name_` type names, the `.msg` fields in
order, XCDR1. Nothing here comes from mdrlat."""
from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    header: Header = field(default_factory=Header)
    angle_min: float32 = 0.0
    angle_max: float32 = 0.0
    angle_increment: float32 = 0.0
    time_increment: float32 = 0.0
    scan_time: float32 = 0.0
    range_min: float32 = 0.0
    range_max: float32 = 0.0
    ranges: sequence[float32] = field(default_factory=list)
    intensities: sequence[float32] = field(default_factory=list)


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    encoding: str = ""
    is_bigendian: uint8 = 0
    step: uint32 = 0
    data: sequence[uint8] = field(default_factory=list)


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


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
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose = field(default_factory=Pose)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class TwistStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TwistStamped_"):
    header: Header = field(default_factory=Header)
    twist: Twist = field(default_factory=Twist)


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist = field(default_factory=Twist)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)


@dataclass
class BrokenLaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    """A LaserScan's type name over bytes that are not a LaserScan: a header, then a
    sequence length that runs past the end of the sample."""
    header: Header = field(default_factory=Header)
    angle_min: float32 = 0.0
    count: uint32 = 0


@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: array[uint8, 16] = field(default_factory=lambda: [0] * 16)  # Iron and later


@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: str = ""
    node_name: str = ""
    reader_gid_seq: sequence[Gid] = field(default_factory=list)
    writer_gid_seq: sequence[Gid] = field(default_factory=list)


@dataclass
class ParticipantEntitiesInfo(IdlStruct,
                              typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    """What every ROS 2 participant announces on `ros_discovery_info`; `ros2 node list`
    reads it."""
    gid: Gid = field(default_factory=Gid)
    node_entities_info_seq: sequence[NodeEntitiesInfo] = field(default_factory=list)


# --- DDS plumbing shared by the scripts ---------------------------------------------------
from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

# What drivers publish with: ROS 2's sensor-data profile (best effort, keep last 5), XCDR1.
SENSOR_DATA = Qos(
    Policy.Reliability.BestEffort,
    Policy.Durability.Volatile,
    Policy.History.KeepLast(5),
    Policy.DataRepresentation(use_cdrv0_representation=True),
)
# ROS 2's default profile, as a base subscribes to cmd_vel and most odometry is published.
RELIABLE = Qos(
    Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
    Policy.Durability.Volatile,
    Policy.History.KeepLast(10),
    Policy.DataRepresentation(use_cdrv0_representation=True),
)


# How rmw layers publish and read ros_discovery_info.
DISCOVERY = Qos(
    Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
    Policy.Durability.TransientLocal,
    Policy.History.KeepLast(16),
)


def writer(dp, topic, kind, qos):
    return DataWriter(dp, Topic(dp, "rt" + topic, kind), qos=qos)


def reader(dp, topic, kind, qos):
    return DataReader(dp, Topic(dp, "rt" + topic, kind), qos=qos)


def any_sample(r):
    return ReadCondition(r, ViewState.Any | InstanceState.Any | SampleState.Any)


def listen_twists(dp, cmd, stamped, stop, out):
    """Appends (time, v, w) of every command `cmd` receives to `out` until `stop` is set
    (the base's side of cmd_vel; InvalidSamples, a writer leaving, are skipped)."""
    import time
    from cyclonedds.core import WaitSet
    ws = WaitSet(dp)
    ws.attach(any_sample(cmd))
    while not stop.is_set():
        ws.wait(duration(milliseconds=50))
        for m in cmd.take(N=100):
            if not isinstance(m, TwistStamped if stamped else Twist):
                continue
            t = m.twist if stamped else m
            out.append((time.time(), t.linear.x, t.angular.z))
