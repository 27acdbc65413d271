"""ROS 2 message types as cyclonedds IDL dataclasses (imported only with cyclonedds).

The DDS names are those rmw_cyclonedds gives the ROS 2 types (``<package>::msg::dds_::
<Type>_``); the structs are final (plain XCDR1, as rmw_cyclonedds publishes), so a ROS 2
node on the same domain receives them as ``sensor_msgs/msg/JointState``. No
``from __future__ import annotations`` here: cyclonedds resolves the field types at runtime.
"""

from dataclasses import dataclass

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import float64, int32, sequence, uint32


@final
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    """``builtin_interfaces/msg/Time``: seconds and nanoseconds (system clock)."""

    sec: int32
    nanosec: uint32


@final
@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    """``std_msgs/msg/Header``."""

    stamp: Time
    frame_id: str


@final
@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    """``sensor_msgs/msg/JointState``: names, positions (rad), velocities, efforts."""

    header: Header
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]
