#!/usr/bin/env python3
"""ROS 2 nodes written the way most are, for the determinism tests of the ros2: controller
kind: none synchronises its inputs by stamp the way examples/ros2/follower_node.py does.

``usual.py STYLE`` drives toward the current goal (``/goal_pose``) and slows and turns away
from what the laser sees ahead, in one of these styles:

- ``scan_callback``: acts in its scan callback with the latest odometry and goal (its scan
  subscription made first, so a scan and an odometry message ready together run in that order);
- ``timer``: acts on a 10 Hz timer on simulated time with the latest scan, odometry and goal
  (Nav2's controller server runs on such a rate loop);
- ``multi_threaded``: ``timer`` spun by rclpy's multi-threaded executor (4 threads) with every
  callback in one reentrant callback group, so callbacks may run at once;
- ``events_executor``: ``scan_callback`` spun by rclpy's experimental EventsExecutor, a turn
  at a time with a timeout (its ``spin()``, and ``spin_once()`` with no timeout, keep a core busy
  and run no callback in the Kilted wheels: docs/ros2.md, "A node that does not answer");
- ``approximate_sync``: pairs scan and odometry by stamp within a slop, as message_filters'
  ApproximateTimeSynchronizer does (message_filters has no wheel), and acts on each pair;
- ``goal_once``: reads the route from ``/plan`` once at start (then drops the subscription) and
  acts in its scan callback with the latest odometry;
- ``goal_once_reset``: ``goal_once`` with a reset service (``~/reset``, std_srvs/Trigger) that
  reads the route once more, as a node kept alive across runs (``keep_alive``) must;
- ``wall_clock``: a mistake, not a style: acts in its scan callback, but integrates its heading
  error over the wall clock's time between scans (a steady clock, not the messages' stamps),
  so what it answers depends on the machine's timing and no run repeats;
  ``sitgen check-controller`` must say so.

Default QoS everywhere except the scan (sensor data, as Nav2 subscribes to it). Where
``USUAL_START_LOG`` names a file, the node appends to it the seconds from its process's start to
its node made (``benches/ros2_start.py``). ``USUAL_COST_MS`` makes each answer cost that many
milliseconds of processor time first, as a planner's would (tests/test_load.py).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import sys
import time
from typing import Any

import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry, Path
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Trigger

STYLE = sys.argv[1]
COST_S = float(os.environ.get("USUAL_COST_MS", "0")) / 1000


def stamp_s(msg: Any) -> float:
    return float(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)


def steer(odom: Odometry, goal: tuple[float, float], scan: LaserScan) -> Twist:
    """Toward ``goal``, slower and turning away when the laser sees something close ahead."""
    pose = odom.pose.pose
    heading = 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)
    bearing = math.atan2(goal[1] - pose.position.y, goal[0] - pose.position.x) - heading
    bearing = math.atan2(math.sin(bearing), math.cos(bearing))
    n = len(scan.ranges)
    ahead = [r for r in scan.ranges[n // 3 : 2 * n // 3] if math.isfinite(r)]
    nearest = min(ahead, default=scan.range_max)
    left = sum(r for r in scan.ranges[n // 2 :] if math.isfinite(r))
    right = sum(r for r in scan.ranges[: n // 2] if math.isfinite(r))
    command = Twist()
    command.linear.x = max(0.0, min(0.6, 0.6 * (nearest - 0.4)))
    away = 0.8 * (1.0 if left > right else -1.0) if nearest < 1.2 else 0.0
    command.angular.z = max(-1.5, min(1.5, 1.5 * bearing + away))
    return command


def seconds_since_start() -> float:
    """Seconds since this process started (Linux's /proc: its start in clock ticks since boot)."""
    with open("/proc/self/stat") as stat, open("/proc/uptime") as uptime:
        started = int(stat.read().rpartition(")")[2].split()[19]) / os.sysconf("SC_CLK_TCK")
        return float(uptime.read().split()[0]) - started


class Usual(Node):
    def __init__(self) -> None:
        super().__init__(f"usual_{STYLE}")
        group = ReentrantCallbackGroup() if STYLE == "multi_threaded" else None
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        self.scan: LaserScan | None = None
        self.odom: Odometry | None = None
        self.goal: tuple[float, float] | None = None
        if STYLE in (
            "scan_callback",
            "events_executor",
            "goal_once",
            "goal_once_reset",
            "wall_clock",
        ):
            self.create_subscription(LaserScan, "/scan", self.on_scan, qos_profile_sensor_data)
        else:
            self.create_subscription(
                LaserScan, "/scan", self.keep_scan, qos_profile_sensor_data, callback_group=group
            )
        self.create_subscription(Odometry, "/odom", self.on_odom, 10, callback_group=group)
        if STYLE.startswith("goal_once"):
            self.read_plan()
        else:
            self.create_subscription(
                PoseStamped, "/goal_pose", self.on_goal, 10, callback_group=group
            )
        if STYLE in ("timer", "multi_threaded"):
            self.create_timer(0.1, self.on_timer, callback_group=group)
        if STYLE == "goal_once_reset":
            self.create_service(Trigger, "~/reset", self.on_reset)
        self.integral, self.last_wall = 0.0, time.monotonic()
        self.pending: dict[str, dict[float, Any]] = {"scan": {}, "odom": {}}

    def read_plan(self) -> None:
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.plan = self.create_subscription(Path, "/plan", self.on_plan, latched)

    def on_reset(self, _: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.goal = None
        self.read_plan()
        response.success = True
        return response

    def on_goal(self, goal: PoseStamped) -> None:
        self.goal = (goal.pose.position.x, goal.pose.position.y)

    def on_plan(self, path: Path) -> None:
        # Read once: the last waypoint is the goal.
        self.goal = (path.poses[-1].pose.position.x, path.poses[-1].pose.position.y)
        self.destroy_subscription(self.plan)

    def keep_scan(self, scan: LaserScan) -> None:
        self.scan = scan
        if STYLE == "approximate_sync":
            self.synchronise("scan", scan)

    def on_odom(self, odom: Odometry) -> None:
        self.odom = odom
        if STYLE == "approximate_sync":
            self.synchronise("odom", odom)

    def on_scan(self, scan: LaserScan) -> None:
        self.scan = scan
        self.act()

    def on_timer(self) -> None:
        self.act()

    def synchronise(self, topic: str, msg: Any, slop_s: float = 0.05, queue: int = 10) -> None:
        """message_filters' ApproximateTimeSynchronizer (Python): the first combination of
        queued messages within ``slop_s`` of each other is handed on and dropped."""
        self.pending[topic][stamp_s(msg)] = msg
        while len(self.pending[topic]) > queue:
            del self.pending[topic][min(self.pending[topic])]
        for scan_t, odom_t in itertools.product(self.pending["scan"], self.pending["odom"]):
            if abs(scan_t - odom_t) <= slop_s:
                scan, odom = self.pending["scan"].pop(scan_t), self.pending["odom"].pop(odom_t)
                self.scan, self.odom = scan, odom
                self.act()
                return

    def act(self) -> None:
        if self.scan is None or self.odom is None or self.goal is None:
            return
        if COST_S:
            began = time.thread_time()
            while time.thread_time() - began < COST_S:
                pass
        command = steer(self.odom, self.goal, self.scan)
        if STYLE == "wall_clock":
            now = time.monotonic()
            self.integral += command.angular.z * (now - self.last_wall)
            self.last_wall = now
            command.angular.z = max(-1.5, min(1.5, command.angular.z + 0.5 * self.integral))
        self.cmd.publish(command)


def main() -> None:
    rclpy.init()
    node = Usual()
    if log := os.environ.get("USUAL_START_LOG"):
        with open(log, "a") as out:
            out.write(f"{seconds_since_start():.2f}\n")
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        if STYLE == "multi_threaded":
            executor = MultiThreadedExecutor(num_threads=4)
            executor.add_node(node)
            executor.spin()
        elif STYLE == "events_executor":
            events = EventsExecutor()
            events.add_node(node)
            while rclpy.ok():
                events.spin_once(timeout_sec=1.0)
        else:
            rclpy.spin(node)


if __name__ == "__main__":
    main()
