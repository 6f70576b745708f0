"""A sampling planner that costs milliseconds a step: the worked example of "A planner that
costs milliseconds" in docs/your-controller.md.

What it does: every step it rolls out a grid of (v, omega) commands for ``horizon_s`` seconds
(unicycle model, ``rollout_dt_s`` steps), drops those whose path comes within ``clearance_m``
of a laser return, and drives the one that scores best on heading to the next waypoint,
clearance and speed (the dynamic window approach's objective, in the robot's own frame).

Why: it is what a real local planner costs — a few milliseconds of Python and numpy a step,
hundreds of times a trivial class — and it fails the way slow planners do: it orbits a
waypoint its sampled turn rates cannot reach, and it trusts a scan that does not show a peer
about to cross.

Parameters (``--param NAME=VALUE``, keyword arguments of the class): ``max_speed_m_s``
(default 0.6), ``max_turn_rad_s`` (default 1.0), ``speeds`` and ``turns`` samples of each
(default 6 and 15), ``horizon_s`` (default 2.0), ``rollout_dt_s`` (default 0.1),
``clearance_m`` (default 0.45), ``heading_weight``, ``clearance_weight``, ``speed_weight``
(default 1.0, 0.3, 0.2).

Source: Fox, Burgard & Thrun (1997), "The dynamic window approach to collision avoidance",
IEEE Robotics & Automation Magazine 4(1), its objective without the window's acceleration
bounds (sitgen's simulator limits the robot).

    sitgen check-controller python:examples/controllers/sampling.py:Sampling
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


class Sampling:
    """Rolls out a grid of commands each step and drives the best one."""

    def __init__(
        self,
        max_speed_m_s: float = 0.6,
        max_turn_rad_s: float = 1.0,
        speeds: float = 6,
        turns: float = 15,
        horizon_s: float = 2.0,
        rollout_dt_s: float = 0.1,
        clearance_m: float = 0.45,
        heading_weight: float = 1.0,
        clearance_weight: float = 0.3,
        speed_weight: float = 0.2,
    ) -> None:
        v = np.linspace(0.0, max_speed_m_s, int(speeds))
        w = np.linspace(-max_turn_rad_s, max_turn_rad_s, int(turns))
        self.v, self.w = (a.ravel() for a in np.meshgrid(v, w))
        self.max_speed_m_s = max_speed_m_s
        self.steps = max(1, round(horizon_s / rollout_dt_s))
        self.dt_s = rollout_dt_s
        self.clearance_m = clearance_m
        self.weights = (heading_weight, clearance_weight, speed_weight)
        self.waypoints: list[tuple[float, float]] = []

    def reset(self, info: dict[str, Any]) -> None:
        self.waypoints = [tuple(w) for w in info["waypoints"]]

    def rollouts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every command's path in the robot's frame: x, y, heading, (commands, steps)."""
        t = self.dt_s * np.arange(1, self.steps + 1)
        heading = np.outer(self.w, t)
        turning = np.abs(self.w) > 1e-9
        radius = np.where(turning, self.v / np.where(turning, self.w, 1.0), 0.0)[:, None]
        x = np.where(turning[:, None], radius * np.sin(heading), np.outer(self.v, t))
        y = np.where(turning[:, None], radius * (1 - np.cos(heading)), 0.0)
        return x, y, heading

    def act(self, obs: Any) -> tuple[float, float]:
        if obs.waypoints_reached >= len(self.waypoints):
            return 0.0, 0.0
        px, py, ph = obs.pose
        gx, gy = self.waypoints[obs.waypoints_reached]
        # The goal and the laser's returns in the robot's frame.
        c, s = math.cos(-ph), math.sin(-ph)
        goal = ((gx - px) * c - (gy - py) * s, (gx - px) * s + (gy - py) * c)
        hits = obs.ranges < obs.max_range
        points = np.stack(
            [
                obs.ranges[hits] * np.cos(obs.angles[hits]),
                obs.ranges[hits] * np.sin(obs.angles[hits]),
            ],
            axis=1,
        )
        x, y, heading = self.rollouts()
        if len(points):
            gaps = np.hypot(x[..., None] - points[:, 0], y[..., None] - points[:, 1])
            clearance = gaps.min(axis=(1, 2))
        else:
            clearance = np.full(len(self.v), 10.0)
        bearing = np.arctan2(goal[1] - y[:, -1], goal[0] - x[:, -1]) - heading[:, -1]
        aim = 1.0 - np.abs(np.arctan2(np.sin(bearing), np.cos(bearing))) / math.pi
        score = (
            self.weights[0] * aim
            + self.weights[1] * np.minimum(clearance, 2.0) / 2.0
            + self.weights[2] * self.v / self.max_speed_m_s
        )
        score[clearance < self.clearance_m] = -np.inf
        best = int(np.argmax(score))
        if not np.isfinite(score[best]):
            return 0.0, 0.0
        return float(self.v[best]), float(self.w[best])
