#!/usr/bin/env python3
"""A ``ros2:`` node with a trivial reply: one constant command for each scan, nothing else
(rclpy, the way a ROS 2 node is usually written). ``make bench`` drives it in lockstep: what
a step costs beyond the run's own is sitgen's hand-over and the node's rclpy turn.

``trivial_node.py events_executor`` spins it with rclpy's experimental EventsExecutor instead,
a turn at a time (docs/ros2.md, "A node that does not answer": its ``spin()`` runs no callback
in the Kilted wheels)."""

from __future__ import annotations

import contextlib
import sys

import rclpy
from geometry_msgs.msg import Twist
from rclpy.executors import ExternalShutdownException
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan


class TrivialNode(Node):
    def __init__(self) -> None:
        super().__init__("trivial_node")
        self.command = Twist()
        self.command.linear.x, self.command.angular.z = 0.3, 0.1
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_subscription(LaserScan, "/scan", self.on_scan, qos_profile_sensor_data)

    def on_scan(self, _: LaserScan) -> None:
        self.cmd.publish(self.command)


def main() -> None:
    rclpy.init()
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        if sys.argv[1:] == ["events_executor"]:
            events = EventsExecutor()
            events.add_node(TrivialNode())
            while rclpy.ok():
                events.spin_once(timeout_sec=1.0)
        else:
            rclpy.spin(TrivialNode())


if __name__ == "__main__":
    main()
