"""The messages of a ``ros2:`` run as sitgen sends and reads them: the loopback simulator's topic
names and REP 105 frames, simulated time as a ROS time, a heading as a quaternion, the scan's
fields for the run's laser, the map's cells, and a /cmd_vel answer as numbers.

What it does: plain functions of the run's values and the message classes handed in (rclpy
and the message packages are imported by the bridge, never here), shared by the bridge's Python
side (bridge.py), its C side's inputs (native.py) and the rosbag2 export
(presentation/rosbag.py), so the three say the same thing.

Why: a run read back from its bag, or handed over in C, must carry exactly the values the
Python side sends.

Parameters: none.

Source: Nav2's loopback simulator (topics, frames), REP 105 (frames), nav_msgs/OccupancyGrid
(row 0 at the map's origin), builtin_interfaces/Time.
"""

from __future__ import annotations

import array
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class Topics:
    """sitgen's side of the contract (a node remaps its own names to these)."""

    clock: str = "/clock"
    scan: str = "/scan"
    odom: str = "/odom"
    plan: str = "/plan"
    goal: str = "/goal_pose"
    map: str = "/map"
    initialpose: str = "/initialpose"
    tf: str = "/tf"
    tf_static: str = "/tf_static"
    cmd_vel: str = "/cmd_vel"
    reset: str = "reset"
    """A node's reset service: any std_srvs Trigger or Empty service named ``/reset`` or
    ending in ``/reset`` (``/my_node/reset``, as a node's ``~/reset`` is)."""


@dataclass(frozen=True)
class Frames:
    """REP 105 frame ids, as Nav2's loopback simulator names them."""

    map: str = "map"
    odom: str = "odom"
    base: str = "base_link"
    scan: str = "base_scan"


TOPICS = Topics()
FRAMES = Frames()


def sec_nanosec(t: float, later_s: float = 0.0) -> tuple[int, int]:
    """Simulated time ``t`` seconds (plus ``later_s``, added in whole nanoseconds, so that
    a period's end is exactly a timer's deadline) as a ROS time's (sec, nanosec)."""
    ns = round(t * 1e9) + round(later_s * 1e9)
    return ns // 1_000_000_000, ns % 1_000_000_000


def stamp(msg: dict[str, Any], t: float, later_s: float = 0.0) -> Any:
    """A builtin_interfaces/Time for simulated time ``t`` (plus ``later_s``; ``msg``: the
    message types)."""
    sec, nanosec = sec_nanosec(t, later_s)
    return msg["Time"](sec=sec, nanosec=nanosec)


def quaternion(heading: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``heading`` about z."""
    return (0.0, 0.0, math.sin(heading / 2), math.cos(heading / 2))


def scan_constants(info: Mapping[str, Any], period_s: float) -> tuple[float, ...]:
    """The scan's constant fields for the laser the run's reset info describes, as
    :func:`laser_scan` sets them."""
    laser, angles = info["laser"], info["laser"]["angles"]
    increment = float((angles[-1] - angles[0]) / (len(angles) - 1)) if len(angles) > 1 else 0.0
    return (
        float(angles[0]),
        float(angles[-1]),
        increment,
        0.0,
        period_s,
        float(laser.get("min_range_m", 0.0)),
        float(laser["range_m"]),
    )


def laser_scan(msg: dict[str, Any], info: Mapping[str, Any], ranges: Any, t: float) -> Any:
    """A sensor_msgs/LaserScan of ``ranges`` at simulated time ``t``, for the laser that the
    run's reset info describes (``laser``: ``angles``, ``range_m``, ``min_range_m``)."""
    scan = msg["LaserScan"]()
    scan.header.stamp, scan.header.frame_id = stamp(msg, t), FRAMES.scan
    (
        scan.angle_min,
        scan.angle_max,
        scan.angle_increment,
        scan.time_increment,
        scan.scan_time,
        scan.range_min,
        scan.range_max,
    ) = scan_constants(info, control_period_s(info))
    scan.ranges = float32s(ranges)
    return scan


def float32s(values: Any) -> array.array[float]:
    """``values`` as a message's float32 sequence: an array.array, which rclpy takes as it is
    (a list it checks value by value), rounded to float32 as rclpy would round a list."""
    return array.array("f", np.asarray(values, dtype=np.float32).tobytes())


def occupancy_data(occupied: npt.NDArray[np.bool_]) -> npt.NDArray[np.int8]:
    """An OccupancyGrid's ``data`` for a map whose row 0 is its top edge (sitgen's): row-major
    from the bottom edge (ROS's: row 0 at the origin), 100 occupied and 0 free."""
    return np.where(np.flipud(occupied), 100, 0).astype(np.int8).ravel()


def control_period_s(info: Mapping[str, Any]) -> float:
    """The run's control period (its reset info's), in seconds."""
    return float(info.get("control_period_s", info.get("dt_s", 0.1)))


def answer_of(message: Any, stamped: bool) -> tuple[float, float, float]:
    """A /cmd_vel message (a TwistStamped where ``stamped``, else a Twist) as (v, ω, its
    stamp in seconds; 0 for a Twist)."""
    twist = message.twist if stamped else message
    at = seconds(message.header.stamp) if stamped else 0.0
    return float(twist.linear.x), float(twist.angular.z), at


def seconds(time_msg: Any) -> float:
    """A builtin_interfaces/Time in seconds."""
    return float(time_msg.sec) + float(time_msg.nanosec) * 1e-9
