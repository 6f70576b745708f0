#!/usr/bin/env python3
"""A ROS 2 node that goes wrong on purpose, for the tests of the ros2: controller kind.

``misbehaving.py MODE`` answers each scan with a slow forward command (Twist), except:
``crash`` exits with code 3 at its fifth scan; ``hang`` stops answering (and keeps spinning)
after its fifth; ``busy`` never returns from the callback of its sixth (it computes for ever);
``silent`` never publishes; ``busy_at_once`` never returns from its first scan callback;
``crash_on_even_routes`` crashes at once on a route with an even number of waypoints and
otherwise behaves (so that a campaign has both).
"""

from __future__ import annotations

import contextlib
import os
import sys

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Path
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

MODE = sys.argv[1]


class Misbehaving(Node):
    def __init__(self) -> None:
        super().__init__("misbehaving")
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        self.scans = 0
        self.stamps: set[tuple[int, int]] = set()
        self.route: list[object] | None = None
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.create_subscription(Path, "/plan", self.on_plan, latched)
        self.create_subscription(LaserScan, "/scan", self.on_scan, qos_profile_sensor_data)

    def on_plan(self, path: Path) -> None:
        self.route = list(path.poses)

    def on_scan(self, scan: LaserScan) -> None:
        if self.route is None:
            return
        # Counted by stamp: sitgen repeats the first observation until it is answered.
        self.stamps.add((scan.header.stamp.sec, scan.header.stamp.nanosec))
        self.scans = len(self.stamps)
        if MODE == "crash_on_even_routes" and len(self.route) % 2 == 0:
            os._exit(3)
        if MODE == "crash" and self.scans == 5:
            print("misbehaving: crashing on purpose", file=sys.stderr, flush=True)
            os._exit(3)
        if (MODE == "busy" and self.scans > 5) or MODE == "busy_at_once":
            while True:
                pass
        if MODE == "silent" or (MODE == "hang" and self.scans > 5):
            return
        command = Twist()
        command.linear.x = 0.3
        self.cmd.publish(command)


def main() -> None:
    rclpy.init()
    node = Misbehaving()
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        rclpy.spin(node)


if __name__ == "__main__":
    main()
