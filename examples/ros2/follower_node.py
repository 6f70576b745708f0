#!/usr/bin/env python3
"""The route follower (follower.py) as a ROS 2 node, the way a navigation node meets a robot.

Subscribes to ``/plan`` (nav_msgs/Path, transient-local: the route), ``/odom``
(nav_msgs/Odometry) and ``/scan`` (sensor_msgs/LaserScan, sensor-data QoS), and publishes
``/cmd_vel`` as geometry_msgs/TwistStamped (Nav2's default in Kilted; ``-p stamped:=false``
for Twist). It answers each scan once the odometry of the same stamp is in (an exact-time
synchroniser, as message_filters' TimeSynchronizer would), so that its commands do not depend
on which message DDS delivers first, and it does not answer before it has its route: that is
what makes its runs repeatable.

Run it:    sitgen run situation.json --controller 'ros2:python3 examples/ros2/follower_node.py'
Campaign:  sitgen campaign examples/ros2/campaign.toml -o ros2.db
Parameters: those of follower.py (``-p speed_m_s:=0.4``, or the spec's controller ``params``).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import rclpy
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

sys.path.insert(0, str(Path(__file__).resolve().parent))
from follower import Follower


class FollowerNode(Node):  # type: ignore[misc]
    def __init__(self) -> None:
        super().__init__("follower")
        defaults = Follower()
        names = ("speed_m_s", "stop_m", "switch_m", "cone_deg", "turn_gain")
        for name in names:
            self.declare_parameter(name, float(getattr(defaults, name)))
        self.declare_parameter("stamped", True)
        self.follower = Follower(**{name: float(self.get_parameter(name).value) for name in names})
        self.stamped = bool(self.get_parameter("stamped").value)
        self.cmd = self.create_publisher(TwistStamped if self.stamped else Twist, "/cmd_vel", 10)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.create_subscription(PathMsg, "/plan", self.on_plan, latched)
        self.create_subscription(Odometry, "/odom", self.on_odom, 10)
        self.create_subscription(LaserScan, "/scan", self.on_scan, qos_profile_sensor_data)
        self.odom: dict[tuple[int, int], Any] = {}
        self.scans: dict[tuple[int, int], Any] = {}

    def on_plan(self, path: PathMsg) -> None:
        self.follower.follow([(p.pose.position.x, p.pose.position.y) for p in path.poses])

    def on_odom(self, odom: Odometry) -> None:
        self.odom[_key(odom.header.stamp)] = odom
        self.answer()

    def on_scan(self, scan: LaserScan) -> None:
        self.scans[_key(scan.header.stamp)] = scan
        self.answer()

    def answer(self) -> None:
        if self.follower.waypoints == []:
            return  # no route yet: transient-local delivery may trail the first scan
        for key in sorted(set(self.odom) & set(self.scans)):
            # Anything stamped before what is answered now can never be matched.
            for pending in (self.odom, self.scans):
                for older in [k for k in pending if k < key]:
                    del pending[older]
            odom, scan = self.odom.pop(key), self.scans.pop(key)
            pose = odom.pose.pose
            heading = 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)
            v, omega = self.follower.command(
                (pose.position.x, pose.position.y, heading),
                scan.ranges,
                scan.angle_min,
                scan.angle_increment,
            )
            if self.stamped:
                message = TwistStamped()
                message.header.stamp = scan.header.stamp
                message.header.frame_id = "base_link"
                twist = message.twist
            else:
                message = twist = Twist()
            twist.linear.x, twist.angular.z = float(v), float(omega)
            self.cmd.publish(message)


def _key(stamp: Any) -> tuple[int, int]:
    return (int(stamp.sec), int(stamp.nanosec))


def main() -> None:
    rclpy.init()
    node = FollowerNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
