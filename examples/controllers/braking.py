"""A route follower with a braking rule: the worked example of docs/your-controller.md.

What it does: heads for the next waypoint of its route (the one the monitor counts as next,
``obs.waypoints_reached``) and brakes in proportion to the nearest laser return in a narrow cone
ahead, stopping ``brake_m`` short of it.

Why: it is the controller most people write first, and it has the weakness sitgen is for: it
only ever looks ahead and only ever brakes. A peer that crosses from the side or comes from
behind finds it stopped or still driving, and it never steers or backs away; sitgen's campaign
of it shows those failures, ranked, each once.

Parameters (``--param NAME=VALUE``, keyword arguments of the class):
``speed_m_s`` cruising speed, m/s (default 0.6); ``brake_m`` distance ahead at which it stops,
m (default 0.7); ``slow_m`` distance over which it slows before that, m (default 1.5);
``cone_deg`` half-width of the cone it watches, degrees (default 20); ``gain`` turn rate per
radian of heading error, 1/s (default 1.5).

Source: a proportional heading controller with a stopping distance, as in any robotics course.

    sitgen check-controller python:examples/controllers/braking.py:Braking
    sitgen campaign --controller python:examples/controllers/braking.py:Braking --n 100
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


class Braking:
    """Heads for the next waypoint; brakes for what is ahead, and for nothing else."""

    def __init__(
        self,
        speed_m_s: float = 0.6,
        brake_m: float = 0.7,
        slow_m: float = 1.5,
        cone_deg: float = 20.0,
        gain: float = 1.5,
    ) -> None:
        self.speed_m_s = speed_m_s
        self.brake_m = brake_m
        self.slow_m = slow_m
        self.cone_rad = math.radians(cone_deg)
        self.gain = gain
        self.waypoints: list[list[float]] = []

    def reset(self, info: dict[str, Any]) -> None:
        self.waypoints = info["waypoints"]

    def act(self, obs: Any) -> tuple[float, float]:
        if obs.waypoints_reached >= len(self.waypoints):
            return 0.0, 0.0
        x, y, heading = obs.pose
        gx, gy = self.waypoints[obs.waypoints_reached]
        error = math.remainder(math.atan2(gy - y, gx - x) - heading, math.tau)
        ahead = np.abs(obs.angles) < self.cone_rad
        nearest = float(np.min(obs.ranges[ahead])) if ahead.any() else math.inf
        brake = min(1.0, max(0.0, (nearest - self.brake_m) / self.slow_m))
        v = self.speed_m_s * brake * max(0.0, math.cos(error))
        return v, self.gain * error
