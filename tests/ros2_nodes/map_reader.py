#!/usr/bin/env python3
"""A ROS 2 node that reads ``/map`` as a costmap's static layer would (transient local), for
the test that sitgen serves it live: ``map_reader.py OUT.json`` writes what it received (the
grid's size, resolution, frame and data) to OUT.json, then answers every scan with a stop.
"""

from __future__ import annotations

import contextlib
import json
import sys

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import OccupancyGrid
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan


class MapReader(Node):
    def __init__(self, out: str) -> None:
        super().__init__("map_reader")
        self.out = out
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.create_subscription(OccupancyGrid, "/map", self.on_map, latched)
        self.create_subscription(LaserScan, "/scan", self.on_scan, qos_profile_sensor_data)

    def on_map(self, grid: OccupancyGrid) -> None:
        with open(self.out, "w") as f:
            json.dump(
                {
                    "frame": grid.header.frame_id,
                    "width": grid.info.width,
                    "height": grid.info.height,
                    "resolution": grid.info.resolution,
                    "data": list(grid.data),
                },
                f,
            )

    def on_scan(self, _: LaserScan) -> None:
        self.cmd.publish(Twist())


def main() -> None:
    rclpy.init()
    node = MapReader(sys.argv[1])
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        rclpy.spin(node)


if __name__ == "__main__":
    main()
