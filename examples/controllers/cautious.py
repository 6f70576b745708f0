"""A Python controller for sitgen: drive to each waypoint, slow down near anything ahead.

Run it:  sitgen run situation.json --controller python:examples/controllers/cautious.py:Cautious
Check it: sitgen check-controller python:examples/controllers/cautious.py:Cautious

A controller is any object with ``reset(info)`` and ``act(obs) -> (v, omega)``; ``info`` and
``obs`` are described in docs/controller-protocol.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


class Cautious:
    """Heads for the current waypoint; speed falls with the nearest return in a 60° cone."""

    def __init__(self, speed_m_s: float = 0.5, stop_m: float = 0.6, switch_m: float = 0.5) -> None:
        self.speed_m_s = speed_m_s
        self.stop_m = stop_m
        self.switch_m = switch_m
        self.waypoints: list[list[float]] = []
        self.next = 0

    def reset(self, info: dict[str, Any]) -> None:
        self.waypoints = info["waypoints"]
        self.next = 0

    def act(self, obs: Any) -> tuple[float, float]:
        x, y, heading = obs.pose
        while self.next < len(self.waypoints):
            gx, gy = self.waypoints[self.next]
            if math.hypot(gx - x, gy - y) > self.switch_m:
                break
            self.next += 1
        if self.next == len(self.waypoints):
            return 0.0, 0.0
        gx, gy = self.waypoints[self.next]
        error = math.remainder(math.atan2(gy - y, gx - x) - heading, math.tau)
        ahead = np.abs(obs.angles) < math.radians(30)
        nearest = float(np.min(obs.ranges[ahead])) if ahead.any() else math.inf
        slow = min(1.0, max(0.0, (nearest - self.stop_m) / 1.5))
        v = self.speed_m_s * slow * max(0.0, math.cos(error)) if abs(error) < 0.8 else 0.0
        return v, 1.5 * error
