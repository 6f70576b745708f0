#!/usr/bin/env python3
"""A ROS 2 node that reads what sitgen serves, for the tests that it is live: ``/map`` as a
costmap's static layer would (transient local), ``/initialpose`` as Nav2's loopback simulator
does, ``/tf`` and ``/tf_static`` as tf2's listener does (its QoS), and calls of its reset
service (``~/reset``, std_srvs/Empty). ``map_reader.py OUT.json`` writes what it has received
so far (the last grid's size, resolution, frame and data; every initial pose as (x, y,
heading); every transform as (stamp, parent, child, x, y, heading), static ones apart; the
resets; its process id) to OUT.json, and answers every scan with the command its parameters
``speed_m_s`` and ``turn_rad_s`` give (default: stop).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
from typing import Any

import rclpy
from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
from nav_msgs.msg import OccupancyGrid
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Empty

try:
    from tf2_msgs.msg import TFMessage
except ImportError:  # no compiler for sitgen to build it with: the node reads the rest
    TFMessage = None


class MapReader(Node):
    def __init__(self, out: str) -> None:
        super().__init__("map_reader")
        self.out = out
        self.got: dict[str, Any] = {"map": None, "initial_poses": [], "resets": 0}
        self.got.update(tf=[], tf_static=[])
        self.got["pid"] = os.getpid()
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        self.command = Twist()
        self.command.linear.x = float(self.declare_parameter("speed_m_s", 0.0).value)
        self.command.angular.z = float(self.declare_parameter("turn_rad_s", 0.0).value)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        # tf2_ros.TransformListener's subscriptions, made first as a node's tf listener is:
        # messages waiting together are taken in the order the subscriptions were made.
        dynamic = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        static = QoSProfile(
            depth=100,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        if TFMessage is not None:
            self.create_subscription(TFMessage, "/tf", lambda m: self.on_tf("tf", m), dynamic)
            self.create_subscription(
                TFMessage, "/tf_static", lambda m: self.on_tf("tf_static", m), static
            )
        self.create_subscription(OccupancyGrid, "/map", self.on_map, latched)
        self.create_subscription(LaserScan, "/scan", self.on_scan, qos_profile_sensor_data)
        self.create_subscription(PoseWithCovarianceStamped, "/initialpose", self.on_pose, 10)
        self.create_service(Empty, "~/reset", self.on_reset)

    def on_map(self, grid: OccupancyGrid) -> None:
        self.got["map"] = {
            "frame": grid.header.frame_id,
            "width": grid.info.width,
            "height": grid.info.height,
            "resolution": grid.info.resolution,
            "data": list(grid.data),
        }
        self.write()

    def on_pose(self, message: PoseWithCovarianceStamped) -> None:
        pose = message.pose.pose
        heading = 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)
        self.got["initial_poses"].append([pose.position.x, pose.position.y, heading])
        self.write()

    def on_tf(self, topic: str, message: Any) -> None:
        for t in message.transforms:
            stamp = t.header.stamp.sec + t.header.stamp.nanosec * 1e-9
            place, turn = t.transform.translation, t.transform.rotation
            heading = 2.0 * math.atan2(turn.z, turn.w)
            got = [stamp, t.header.frame_id, t.child_frame_id, place.x, place.y, heading]
            self.got[topic].append(got)
        self.write()

    def on_reset(self, _: Empty.Request, response: Empty.Response) -> Empty.Response:
        self.got["resets"] += 1
        self.write()
        return response

    def write(self) -> None:
        with open(f"{self.out}.part", "w") as f:
            json.dump(self.got, f)
        os.replace(f"{self.out}.part", self.out)

    def on_scan(self, _: LaserScan) -> None:
        self.write()
        self.cmd.publish(self.command)


def main() -> None:
    rclpy.init()
    node = MapReader(sys.argv[1])
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        rclpy.spin(node)


if __name__ == "__main__":
    main()
