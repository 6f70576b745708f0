"""Route following with a laser: the logic of the ROS 2 example node, with nothing of ROS in it.

Heads for the current waypoint of its route (switching to the next within ``switch_m``), turns
on the spot when the heading error is large, and slows as the nearest laser return in a cone
ahead (``cone_deg`` either side) nears ``stop_m``; it does not steer around anything, so sitgen
finds where that is not enough. ``follower_node.py`` runs it as a ROS 2 node and
``follower_cmd.py`` as a ``cmd:`` program, so the two can be timed against each other on the
same decisions (``make bench``).

Parameters: ``speed_m_s`` (m/s, default 0.5), ``stop_m`` (m, default 0.6), ``switch_m`` (m,
default 0.5), ``cone_deg`` (degrees, default 30), ``turn_gain`` (1/s, default 1.5).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field


@dataclass
class Follower:
    speed_m_s: float = 0.5
    stop_m: float = 0.6
    switch_m: float = 0.5
    cone_deg: float = 30.0
    turn_gain: float = 1.5
    waypoints: list[tuple[float, float]] = field(default_factory=list)
    next_index: int = 0

    def follow(self, waypoints: Sequence[Sequence[float]]) -> None:
        """Start on a new route."""
        self.waypoints = [(float(w[0]), float(w[1])) for w in waypoints]
        self.next_index = 0

    def command(
        self,
        pose: Sequence[float],
        ranges: Sequence[float],
        angle_min: float,
        angle_increment: float,
    ) -> tuple[float, float]:
        """(v m/s, omega rad/s) at ``pose`` (x, y, heading) for a scan of ``ranges``."""
        x, y, heading = pose
        while self.next_index < len(self.waypoints) and (
            math.dist(self.waypoints[self.next_index], (x, y)) <= self.switch_m
        ):
            self.next_index += 1
        if self.next_index == len(self.waypoints):
            return 0.0, 0.0
        gx, gy = self.waypoints[self.next_index]
        error = math.remainder(math.atan2(gy - y, gx - x) - heading, math.tau)
        cone = math.radians(self.cone_deg)
        ahead = [r for k, r in enumerate(ranges) if abs(angle_min + k * angle_increment) < cone]
        slow = min(1.0, max(0.0, (min(ahead, default=math.inf) - self.stop_m) / 1.5))
        v = self.speed_m_s * slow * max(0.0, math.cos(error)) if abs(error) < 0.8 else 0.0
        return v, self.turn_gain * error
